"""Two robots, one field, simulated: ``python tests/bench/bench_fleet_sim.py [--json out.json]``.

A 500-plot field (20 rows x 25 plots at ENGR's plot and lane sizes) surveyed in the
simulator (:mod:`phenorover.eval.fleet`) three times, on the same world, seed and
real-time factor:

1. one robot, the plan of one robot;
2. two robots, the plan split between them (each mission takes its share, each robot
   from and back to its home beside the field, lane segments reserved between the
   missions over Zenoh);

both planned with the robots parked by the locations (``PlanOptions.home`` ``near``:
the lone robot and the two alike, beside the edge lanes at the cross lane nearest the
locations, :func:`common.lanes.homes`), so that neither pays a drive from the field's
corner that the other does not;
3. the same two robots again, with robot 1's mission supervisor killed (SIGKILL; its
   launcher starts it again) a third of the way through and robot 2 cut off from
   everything (its router's link) for 30 s of wall time half way through.

For each: the field time (sim time, first mission's start to the last one's end),
lane-segment conflicts against the truth of both robots' positions (their bodies
reaching one segment, :mod:`common.lanes`), and the locations scanned other than
exactly once, from the mission logs.

Figures are reported, never asserted; an experiment that fails makes it exit 1.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
os.environ.setdefault("NUMBA_CACHE_DIR", str(Path(__file__).resolve().parents[2] / ".cache/numba"))

from common.battery import Pace
from common.config import dump_toml
from common.messages.plan import PlanOptions
from phenorover.eval import fleet, fleet_score
from phenorover.eval.error_models import from_manifest
from phenorover.eval.fields import engr_sized
from phenorover.eval.results import Bench, Goal

ROWS, PLOTS = 20, 25
RTF = 8.0  # the world's pace, the same in every run
SEED = 1
PARTITION_S = 30.0  # wall
# the plans' estimate only (the split balances it); the robots go at their own pace
OPTIONS = PlanOptions(pace=Pace(speed=0.3, location_s=120.0), home="near")
RATIO = Goal(
    "<=",
    0.6,
    "the drive each robot pays between its home and its share, and the waits for "
    "each other's lanes (in the mission logs): a split on the robots' measured pace "
    "rather than the plan's estimate, or homes chosen for each share",
)
NONE = Goal("<=", 0.0, "the reservations: every conflict's segment and time is in the details")


def survey(out: Path, field: Path, robots: int, faults: fleet.Faults) -> dict[str, Any]:
    t0 = time.monotonic()
    o = fleet.run(field, out, robots, OPTIONS, rtf=RTF, seed=SEED, faults=faults, timeout_s=5400)
    wall = time.monotonic() - t0
    finals = {
        n: None if s is None else (s.phase.value, s.scans_done, s.scans_total)
        for n, s in o.final.items()
    }
    s = fleet_score.score(o, field)
    print(robots, "robots:", finals, s, o.notes, flush=True)
    return {
        "wall_s": wall,
        "field_s": s.field_s,
        "conflicts": s.conflicts,
        "closest_m": s.closest_m,
        "missing": s.missing,
        "twice": s.twice,
        "per_robot": s.per_robot,
        "locations": len(o.plan.selected),
        "examples": s.examples,
        "finals": finals,
        "notes": o.notes,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path, help="write the figures as JSON here")
    ap.add_argument("--keep", type=Path, default=None, help="keep the runs here")
    args = ap.parse_args()
    root = args.keep or Path(tempfile.mkdtemp(prefix="bench_fleet_sim-"))
    root.mkdir(parents=True, exist_ok=True)
    field = root / "field500.toml"
    field.write_text(dump_toml(engr_sized(ROWS, PLOTS, "f500")))
    models = from_manifest(fleet.DEPLOY / "world.toml")
    models["pace"] = f"the world at {RTF:g}x real time, seed {SEED}; the follower's own speeds"
    bench = Bench("bench_fleet_sim", error_models=models)
    out: dict[str, Any] = {}
    runs = {
        "one robot": (1, fleet.Faults()),
        "two robots": (2, fleet.Faults()),
    }
    for name, (n, faults) in runs.items():
        try:
            out[name] = survey(root / name.replace(" ", "-"), field, n, faults)
        except Exception as exc:
            bench.fail(name, f"{type(exc).__name__}: {exc}")
    clean = out.get("two robots", {}).get("field_s")
    if clean:  # the faults at a third and half of the clean survey's time
        faults = fleet.Faults(
            kill=("rover1", clean / 3), partition=("rover2", clean / 2, PARTITION_S)
        )
        try:
            out["faulted"] = survey(root / "faulted", field, 2, faults)
        except Exception as exc:
            bench.fail("faulted", f"{type(exc).__name__}: {exc}")
    one, two, bad = out.get("one robot", {}), out.get("two robots", {}), out.get("faulted", {})
    ratio = two["field_s"] / one["field_s"] if one.get("field_s") and two.get("field_s") else None
    bench.figure(
        "two robots' field time / one robot's (simulated, same world, seed and pace)",
        ratio,
        "x",
        goal=RATIO,
        headline=True,
        missing="a run failed",
        note=f"{one.get('locations')} locations; one robot {one.get('field_s', 0) / 3600:.2f} h, "
        f"two {two.get('field_s', 0) / 3600:.2f} h (sim time), shares {two.get('per_robot')}",
    )
    for name, e in (
        ("two robots", two),
        ("two robots, a supervisor killed and a 30 s partition", bad),
    ):
        bench.figure(
            f"{name}: lane-segment conflicts against the truth",
            e.get("conflicts"),
            "samples",
            goal=NONE,
            headline=True,
            missing="the run failed",
            note=f"truth at 10 Hz; the robots came within {e.get('closest_m', 0):.2f} m",
        )
        wrong = None if not e else len(e["missing"]) + len(e["twice"])
        bench.figure(
            f"{name}: locations not scanned exactly once",
            wrong,
            "locations",
            goal=NONE,
            headline=True,
            missing="the run failed",
            note=f"missing {e.get('missing')}, twice {e.get('twice')}; "
            + "; ".join(e.get("notes", [])),
        )
    for name, e in out.items():
        bench.figure(
            f"{name}: wall time", e.get("wall_s"), "s", missing="failed", note=f"at {RTF:g}x"
        )
    return bench.finish(args.json, out)


if __name__ == "__main__":
    sys.exit(main())
