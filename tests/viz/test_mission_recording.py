"""A short simulated survey with the dashboard saving one .rrd per mission, checked
with rerun's own tools: the file verifies and holds the field, route, robot and
clouds."""

from __future__ import annotations

import signal
from pathlib import Path

from common.client import wait_alive
from common.messages.mission import MissionPhase
from tests.conftest import Procs
from tests.integration.test_mission import SERVICES, Deployment
from tests.viz import rrd

VIZ = '[services.viz]\nsave = "{run_dir}/{mission}/survey.rrd"\n'


def test_survey_leaves_a_verified_recording_with_the_whole_scene(
    procs: Procs, tmp_path: Path
) -> None:
    d = Deployment(procs, tmp_path, VIZ)
    try:
        assert wait_alive(d.session, {*SERVICES, "viz"}, timeout=60)
        s = d.start()
        final = d.wait(lambda x: x.mission == s.mission and x.phase in (MissionPhase.DONE,))
        assert final.scans_done == 3
        # the footer is written when the dashboard stops
        d.up.send_signal(signal.SIGTERM)
        assert d.up.wait(timeout=20) == 0
    finally:
        d.close()
    path = d.runs / s.mission / "survey.rrd"
    assert path.exists(), sorted(p.name for p in (d.runs / s.mission).iterdir())
    r = rrd.verify(path)
    assert r.returncode == 0, r.stdout + r.stderr
    paths = rrd.entity_paths(path)
    expected = {
        "/field/plots",
        "/field/cells",
        "/field/selected",
        "/route/legs",
        "/robot/estimate",
        "/robot/estimate/body",
        "/robot/truth",
        "/robot/trail/0000",
        "/gnss/fix1",
        "/gnss/fix2",
        "/errors/cross_track_m",
        "/mission/log",
        "/scanner/progress",
        "/clouds/scan_001",
        "/clouds/scan_002",
        "/clouds/scan_003",
    }
    assert expected <= paths, f"missing {sorted(expected - paths)}; have {sorted(paths)}"
