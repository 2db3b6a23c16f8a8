"""Breeding-programme scale: ``python tests/bench/bench_scale.py [--json out.json]``.

A field of 100 x 100 plots at ENGR's plot and lane sizes (10,201 candidate locations,
720,000 cells; about 450 x 180 m):

- ``phenorover plan`` on it, the command as a user runs it (a field file, the
  default options: exact visibility, exact cover, the tour's 10 s search): its wall
  time and peak memory, the locations and the cover's status, the tour and its gap to
  the Held-Karp lower bound;
- in the same run, its visibility as the planner computes it (one candidate's table
  moved to every candidate, :mod:`services.planner.lattice`) against casting every
  candidate: the time of each and their ratio, and that the two tables are equal.

Figures are reported, never asserted; an experiment that fails makes it exit 1.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
os.environ.setdefault("NUMBA_CACHE_DIR", str(Path(__file__).resolve().parents[2] / ".cache/numba"))

from common.field import ScannerModel, build_field
from common.messages.plan import PlanResult
from phenorover.eval.fields import engr_sized
from phenorover.eval.results import Bench, Goal
from services.planner.visibility import compute_visibility

ROWS = PLOTS = 100
LAYOUT = engr_sized(ROWS, PLOTS, "plots-100x100")
TARGETS = {"plan_s": 30.0, "plan_gb": 2.0}
GOALS = {
    "plan_s": Goal(
        "<=",
        TARGETS["plan_s"],
        "a shorter tour search (--tour-limit; 10 s of the time), or the cover's CP-SAT "
        "proof on more cores",
    ),
    "plan_gb": Goal(
        "<=", TARGETS["plan_gb"], "the visibility table's pairs in blocks instead of whole"
    ),
}


def plan_command(field_file: Path, out: Path) -> dict[str, Any]:
    """``phenorover plan`` as a user runs it: wall seconds, peak memory (GB) and the
    plan it wrote."""
    cmd = [sys.executable, "-m", "phenorover", "plan", str(field_file), "--out", str(out)]
    log = out.parent / "plan.log"  # a file, not a pipe nobody reads while it runs
    with log.open("w") as err:
        t = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err)
        # ten times the target: a command that hangs fails the experiment
        watchdog = threading.Timer(10 * TARGETS["plan_s"], proc.kill)
        watchdog.start()
        try:
            _, status, usage = os.wait4(proc.pid, 0)  # its own peak memory
        finally:
            watchdog.cancel()
        wall = time.perf_counter() - t
    code = os.waitstatus_to_exitcode(status)
    proc.returncode = code
    if code != 0:
        raise RuntimeError(f"phenorover plan exited {code}: {log.read_text().strip()[-300:]}")
    r = msgspec.json.decode((out / "plan.json").read_bytes(), type=PlanResult)
    return {
        "wall_s": wall,
        "peak_gb": usage.ru_maxrss * 1024 / 1e9,  # KiB on Linux; decimal GB
        "locations": len(r.selected),
        "cover_status": r.cover.status,
        "cover_gap": r.cover.gap,
        "greedy": r.cover.greedy_count,
        "tour_m": r.tour.length,
        "tour_method": r.tour.method,
        "tour_bound_m": r.tour.bound,
        "timings": r.timings,
    }


def visibility_ratio() -> dict[str, Any]:
    """The planner's visibility of the field against casting every candidate, same run."""
    field = build_field(LAYOUT)
    # the kernels compiled (or loaded from the cache) before either is timed
    small = build_field(msgspec.structs.replace(LAYOUT, rows=20, plots_per_row=10))
    for translate in (True, False):
        compute_visibility(small, ScannerModel(max_range=10.0), translate=translate)
    t = time.perf_counter()
    moved = compute_visibility(field, ScannerModel())
    moved_s = time.perf_counter() - t
    t = time.perf_counter()
    cast = compute_visibility(field, ScannerModel(), translate=False)
    cast_s = time.perf_counter() - t
    equal = all(
        np.array_equal(getattr(moved, k), getattr(cast, k))
        for k in ("cand", "cell", "hits", "range_min")
    )
    return {
        "moved_s": moved_s,
        "cast_s": cast_s,
        "pairs": len(moved.cand),
        "equal": equal,
        "candidates": field.n_candidates,
        "cells": field.n_cells,
    }


def record(bench: Bench, out: dict[str, Any], failed: dict[str, str]) -> None:
    p, v = out.get("plan", {}), out.get("visibility", {})
    why_p = failed.get("plan", "not measured")
    why_v = failed.get("visibility", "not measured")
    bench.figure(
        "100 x 100 plots: phenorover plan, wall time",
        p.get("wall_s"),
        "s",
        goal=GOALS["plan_s"],
        headline=True,
        missing=why_p,
        note="the command as a user runs it, with its default 10 s tour search",
    )
    bench.figure(
        "100 x 100 plots: phenorover plan, peak memory",
        p.get("peak_gb"),
        "GB",
        goal=GOALS["plan_gb"],
        headline=True,
        missing=why_p,
    )
    status = p.get("cover_status", "")
    bench.figure(
        f"100 x 100 plots: scan locations, exact cover ({status})",
        p.get("locations"),
        "",
        missing=why_p,
        note=f"greedy cover {p.get('greedy')}",
    )
    tour, bound = p.get("tour_m"), p.get("tour_bound_m")
    bench.figure(
        "100 x 100 plots: the tour's gap to its Held-Karp lower bound",
        None if tour is None or not bound else 100 * (tour / bound - 1),
        "%",
        missing=why_p if tour is None else "the tour was proven optimal: no bound needed",
        note=f"tour {tour or 0:.0f} m ({p.get('tour_method', '')}), bound {bound or 0:.0f} m",
    )
    moved, cast = v.get("moved_s"), v.get("cast_s")
    bench.figure(
        "100 x 100 plots: visibility, one candidate's table moved to every candidate",
        moved,
        "s",
        missing=why_v,
        note=f"{v.get('pairs', 0):,} pairs; "
        + ("equal" if v.get("equal") else "NOT equal")
        + " to the table cast candidate by candidate",
    )
    bench.figure(
        "100 x 100 plots: visibility cast candidate by candidate / moved (same run)",
        None if not moved or cast is None else cast / moved,
        "x",
        missing=why_v,
        note=f"cast {cast or 0:.1f} s",
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path, help="write the figures as JSON here")
    args = ap.parse_args()
    # deterministic geometry and search: no error model
    bench = Bench("bench_scale")
    out: dict[str, Any] = {"layout": msgspec.to_builtins(LAYOUT)}
    failed: dict[str, str] = {}
    with tempfile.TemporaryDirectory() as d:
        f = Path(d) / "plots-100x100.toml"
        given = {k: v for k, v in msgspec.to_builtins(LAYOUT).items() if v is not None}
        f.write_text(msgspec.toml.encode(given).decode())
        try:
            out["plan"] = plan_command(f, Path(d) / "plan")
            print("phenorover plan:", out["plan"])
        except Exception as exc:
            failed["plan"] = f"{type(exc).__name__}: {exc}"
            bench.fail("plan", failed["plan"])
    try:
        out["visibility"] = visibility_ratio()
        print("visibility:", out["visibility"])
        if not out["visibility"]["equal"]:
            bench.fail("visibility", "the moved table differs from the cast one")
    except Exception as exc:
        failed["visibility"] = f"{type(exc).__name__}: {exc}"
        bench.fail("visibility", failed["visibility"])
    record(bench, out, failed)
    return bench.finish(args.json, out)


if __name__ == "__main__":
    sys.exit(main())
