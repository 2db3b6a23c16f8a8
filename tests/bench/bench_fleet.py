"""Several robots, one field: ``python tests/bench/bench_fleet.py [--json out.json]``.

The plan of a field split between two robots (``PlanOptions.robots``,
:mod:`services.planner.fleet`) on a 600-plot field (20 x 30 plots) and the 100 x 100-plot
field, both at ENGR's plot and lane sizes: the slowest robot's time against one
robot's, both the planner's estimate at the same pace and battery, and the split's
own time. These are plan estimates; the simulated survey of two robots is
``bench_fleet_sim``'s.

Figures are reported, never asserted; an experiment that fails makes it exit 1.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
os.environ.setdefault("NUMBA_CACHE_DIR", str(Path(__file__).resolve().parents[2] / ".cache/numba"))

from common.battery import Battery, Pace
from common.messages.plan import PlanOptions
from phenorover.eval.fields import engr_sized
from phenorover.eval.results import Bench
from services.planner.core import plan

FIELDS = {"600 plots": (20, 30), "100 x 100 plots": (100, 100)}
PACE = Pace()  # the mission's default: 0.3 m/s along routes, 300 s a location
# no target: the (two robots in at most 0.6 x one robot's time) is for the
# simulated two-robot survey (bench_fleet_sim); a plan's estimate does not meet it


def experiment(rows: int, plots: int) -> dict[str, Any]:
    r = plan(engr_sized(rows, plots), options=PlanOptions(robots=2, pace=PACE))
    assert r.fleet is not None
    f = r.fleet
    return {
        "locations": len(r.selected),
        "one_robot_h": f.one_robot_s / 3600,
        "slowest_h": f.makespan_s / 3600,
        "ratio": f.makespan_s / f.one_robot_s,
        "shares": [len(p.order) - 2 for p in f.parts],
        "split_s": f.time_s,
        "status": f.status,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path, help="write the figures as JSON here")
    args = ap.parse_args()
    models = {
        "pace": f"{PACE.speed:g} m/s along routes, {PACE.location_s:g} s a location",
        "battery": Battery().describe(),
    }
    bench = Bench("bench_fleet", error_models=models)
    out: dict[str, Any] = {}
    for name, (rows, plots) in FIELDS.items():
        why = "not measured"
        try:
            out[name] = experiment(rows, plots)
            print(name, out[name])
        except Exception as exc:
            why = f"{type(exc).__name__}: {exc}"
            bench.fail(name, why)
        e = out.get(name, {})
        bench.figure(
            f"{name}: two robots' slowest / one robot (plan estimate)",
            e.get("ratio"),
            "x",
            headline=True,
            missing=why,
            note=f"{e.get('locations', 0)} locations split {e.get('shares')}; one robot "
            f"{e.get('one_robot_h', 0):.1f} h, the slowest of two {e.get('slowest_h', 0):.1f} h",
        )
        bench.figure(
            f"{name}: the split's search",
            e.get("split_s"),
            "s",
            missing=why,
            note=f"OR-Tools routing, {e.get('status', '')}: guided local search to its limit",
        )
    return bench.finish(args.json, out)


if __name__ == "__main__":
    sys.exit(main())
