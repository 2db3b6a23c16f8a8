"""``phenorover sim --field`` on a field of its own: a GeoJSON field (not ENGR, not
the manifest's field, elsewhere on the globe, rows at 30 deg) is the field of the whole
deployment, the simulated world included, and its survey scans every location (exit
0); so does a TOML field with no georeference, placed at the default origin; with an
obstacle on the route a location is skipped and the command says which and why and
exits 1."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np

from common.field import FieldLayout, build_field
from common.field_geojson import field_from_geojson
from common.geo import FieldFrame
from services.mission.log import MissionLog
from services.planner.core import plan
from tests.conftest import REPO, Procs, free_port
from tests.integration.test_mission import TEST_HZ

ROWS_BEARING_DEG = 30.0
# one row of three plots, no origin_lat/origin_lon
NO_ORIGIN = REPO / "tests" / "data" / "no_origin.toml"
MINI = FieldLayout(
    name="mini",
    rows=2,
    plots_per_row=3,
    plot_length=2.5,
    plot_width=1.2,
    plot_height=1.5,
    row_spacing=1.0,
    alley_width=1.6,
    headland_width=2.0,
    edge_width=1.5,
)


def mini_geojson() -> dict[str, Any]:
    """MINI's plots as WGS84 polygons, as a breeder's QGIS export would give them."""
    frame = FieldFrame(52.0, 5.0, 0.0, ROWS_BEARING_DEG)
    features = []
    for b in build_field(MINI).plot_boxes:
        xs = np.array([b[0], b[3], b[3], b[0], b[0]])
        ys = np.array([b[1], b[1], b[4], b[4], b[1]])
        lat, lon, _ = frame.field_to_wgs84(xs, ys)
        ring = [[float(a), float(c)] for a, c in zip(lon, lat, strict=True)]
        features.append({"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [ring]}})
    settings = {"name": "mini", "plot_height": 1.5, "headland_width": 2.0, "edge_width": 1.5}
    settings["row_bearing_deg"] = ROWS_BEARING_DEG
    return {"type": "FeatureCollection", "features": features, "phenorover": settings}


def run_sim(
    procs: Procs,
    tmp: Path,
    sim: str = "",
    extra: str = "",
    follower: str = "",
    field: Path | None = None,
    robot: Path | None = None,
    scan_s: float = 20.0,
) -> tuple[int, str, Path]:
    """``phenorover sim --field mini.geojson`` (or ``field``) on a fast deployment;
    ``sim``: lines of the simulator's section, ``extra``: after the mission's,
    ``follower``: the route follower's; ``robot``: a robot description file;
    ``scan_s``: sim seconds a scan takes. Exit code, output, runs."""
    if field is None:
        field = tmp / "mini.geojson"
        field.write_text(json.dumps(mini_geojson()))
    runs = tmp / "runs"
    manifest = tmp / "m.toml"
    # the manifest names ENGR: --field must replace it for every service
    manifest.write_text(f"""machine = "test"
clock = "sim"
field = "engr"
run_dir = "{runs}"
{f'robot = "{robot}"' if robot else ""}
[zenoh]
listen = ["tcp/127.0.0.1:{free_port()}"]
[services.sim]
real_time_factor = 20.0
clock_hz = {TEST_HZ}
{sim}
[services.gnss]
backend = "sim"
# open sky: the crop's shading of the antennas only lengthens every fine positioning
rtk.canopy.noise_gain = 0.0
[services.base]
backend = "sim"
rate_hz = {TEST_HZ}
# safety timers run on sim time: at 20x a process late by 25 ms of wall time is late by
# half a second, so the field's allowances would trip on this machine's scheduling
watchdog_s = 1.0
[services.scanner]
backend = "sim"
storage_dir = "{tmp / "card"}"
sim_scan_time_s = {scan_s}
render_step_deg = 1.0
status_timeout_s = 40.0
[services.nav]
max_fix_age_s = 2.0
[services.nav.follower]
# fine positioning to millimetres is nav-test's subject; these surveys need the scan
# within the arrival tolerance, and a shorter settle saves minutes (the re-approach
# stays: a route resumed after a pause can end centimetres to the side)
fine_settle_s = 5.0
fine_settle_max_s = 5.0
# behaviour, not accuracy: the speed these surveys were timed at, twice the default
max_speed = 0.3
{follower}
[services.planner]
[services.mission]
lease_s = 8.0
nav_lost_s = 20.0
settle_s = 1.0
register_on_done = false
{extra}""")
    log = tmp / "sim.log"
    p = procs.start(
        "-m", "phenorover", "sim", "--manifest", str(manifest), "--field", str(field), log=log
    )
    code = p.wait(timeout=240)
    return code, log.read_text(), runs


def test_a_geojson_field_of_our_own_is_surveyed_end_to_end(procs: Procs, tmp_path: Path) -> None:
    code, out, runs = run_sim(procs, tmp_path)
    assert code == 0, out[-3000:]
    summary = re.search(r"summary: (\S+): done, (\d+)/(\d+) scans done, 0 failed", out)
    assert summary is not None, out[-3000:]
    assert summary[2] == summary[3] == "3", summary[0]
    # the simulated world was the same field, not the manifest's ENGR
    assert re.search(r"sim \| .*world: field mini \(.*mini\.geojson\), 6 plots", out), out[:3000]
    assert "navigation blocked" not in out
    assert len(list((tmp_path / "card").rglob("*.e57"))) == 3
    steps = MissionLog(runs / summary[1] / "mission.db").steps()
    assert [s.status for s in steps] == ["done"] * 3


def test_a_toml_field_without_georeference_is_surveyed_at_the_default_origin(
    procs: Procs, tmp_path: Path
) -> None:
    code, out, runs = run_sim(procs, tmp_path, field=NO_ORIGIN)
    assert code == 0, out[-3000:]
    placed = "field 'h3' has no georeference: placed at the default origin 33.717028 N, 83.308083 W"
    assert placed in out, out[:3000]
    summary = re.search(r"summary: (\S+): done, (\d+)/(\d+) scans done, 0 failed", out)
    assert summary is not None, out[-3000:]
    assert summary[2] == summary[3] and int(summary[3]) >= 2, summary[0]
    assert re.search(r"sim \| .*world: field h3 \(.*no_origin\.toml\), 3 plots", out), out[:3000]
    assert "exited with code" not in out  # no service refused the field and was restarted
    steps = MissionLog(runs / summary[1] / "mission.db").steps()
    assert [s.status for s in steps] == ["done"] * int(summary[3])


def test_a_skipped_location_ends_the_command_with_exit_1_naming_it(
    procs: Procs, tmp_path: Path
) -> None:
    layout, fld = field_from_geojson(json.dumps(mini_geojson()).encode(), "mini")
    first = plan(layout, field=fld).legs[0]
    assert abs(first.x1 - first.x0) > 3.0  # room to stop before a box in its middle
    box = (
        f"world.obstacles = [{{type = 'box', x = {(first.x0 + first.x1) / 2}, "
        f"y = {first.y0}, size_x = 0.3, size_y = 0.3, height = 0.5}}]"
    )
    code, out, _ = run_sim(
        procs,
        tmp_path,
        sim=box,
        # the drive home is the other test's
        extra="blocked_retries = 0\nreturn_to_origin = false",
        follower="obstacle_timeout_s = 3.0",
    )
    assert code == 1, out[-3000:]
    skipped = r"phenorover sim: scan \d+ \(location \d+\): skipped\b.*navigation blocked"
    assert re.search(skipped, out), out[-3000:]
    assert re.search(r"phenorover sim: \d of 3 locations not scanned", out), out[-3000:]
