"""A survey longer than a battery: ``phenorover sim`` of a field whose robot carries a
small battery (the Husky's model, a smaller pack and a hungrier payload) goes to the
Origin for a swap twice,
waits for the simulated operator, comes back and scans every location once; the true
charge never falls below the reserve, and both swaps are in the mission log."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import msgspec
import tomli_w

from common.messages.plan import PlanResult
from services.mission.log import MissionLog
from tests.conftest import REPO, Procs
from tests.integration.test_any_field import run_sim

HUSKY = REPO / "common" / "robots" / "husky.toml"
# A scan of 125 s and about 25 s of positioning and settling, the pace the plan is
# made at, with the payload drawing 240 W (the Husky's 40 W and a heater, say): a
# location then costs what the paper's 7-10 minutes of scanning cost at 40 W, in a
# third of the simulated time. A pack of 50.5 Wh covers one location and the way back
# to the Origin, not two: the plan foretells a swap before each of the last two
# locations for packs of 49 to 52 Wh.
SCAN_S = 125.0
PACE = "pace = { speed = 0.2, location_s = 150.0 }"
CAPACITY_WH = 50.5
PAYLOAD_W = 240.0
SWAP_S = 20.0


def small_battery(d: Path, capacity_wh: float, payload_w: float, swap_s: float) -> Path:
    """The Husky with a pack of ``capacity_wh``, a payload of ``payload_w`` and a swap
    of ``swap_s``."""
    desc = tomllib.loads(HUSKY.read_text())
    pack = {"capacity_wh": capacity_wh, "payload_w": payload_w, "swap_s": swap_s}
    desc["battery"] = {**desc["battery"], **pack}
    path = d / "small-battery.toml"
    path.write_text(tomli_w.dumps(desc))
    return path


def test_a_survey_of_three_batteries_swaps_twice_and_scans_each_location_once(
    procs: Procs, tmp_path: Path
) -> None:
    robot = small_battery(tmp_path, CAPACITY_WH, PAYLOAD_W, SWAP_S)
    code, out, runs = run_sim(procs, tmp_path, robot=robot, extra=PACE, scan_s=SCAN_S)
    assert code == 0, out[-3000:]
    summary = re.search(r"summary: (\S+): done, (\d+)/(\d+) scans done, 0 failed", out)
    assert summary is not None, out[-3000:]
    run = runs / summary[1]
    log = MissionLog(run / "mission.db")
    assert [s.status for s in log.steps()] == ["done"] * 3
    assert len(list((tmp_path / "card").rglob("*.e57"))) == 3  # each location once
    # the truth of the discharge model: never below the reserve, two swaps
    truth = re.search(
        r"battery \(truth\): lowest charge ([\d.]+) % \(reserve (\d+) %\), (\d+) swaps", out
    )
    assert truth is not None, out[-3000:]
    assert float(truth[1]) >= float(truth[2]) and truth[3] == "2", truth[0]
    # both swaps in the mission log, and foretold by the plan
    texts = [e[2] for e in log.events()]
    for k in (1, 2):
        assert any(t.startswith(f"battery swap {k} done") for t in texts), texts
    assert sum("to the Origin for a swap" in t for t in texts) == 2, texts
    plan = msgspec.json.decode((run / "plan.json").read_bytes(), type=PlanResult)
    assert plan.survey is not None and plan.survey.swaps_before == [1, 2], plan.survey
