"""``phenorover plan FIELD``: plan locally (or ask the planner service with
``--remote``), print a summary, write plan.json, plan.geojson, waypoints.csv and
plan.png."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TextIO

import msgspec

from common.client import add_connection_arguments
from common.cluster import ClusterError, add_cluster_arguments, cluster_of
from common.config import ConfigError
from common.field import FieldError
from common.messages.plan import PlanOptions, PlanRequest, PlanResult
from common.robot import load_robot
from services.planner.outputs import write_all
from services.planner.request import request_from_source


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("field", help="example name (engr, spl) or a .toml/.geojson field file")
    p.add_argument("--nav", choices=["br", "aha", "lanes"], default="aha")
    p.add_argument("--cover", choices=["greedy", "exact"], default="exact")
    p.add_argument("--visibility", choices=["exact", "grid"], default="exact")
    p.add_argument("--grid-step", type=float, default=None, metavar="DEG")
    p.add_argument("--coverage", type=float, default=1.0, help="fraction of coverable cells")
    p.add_argument("--min-hits", type=int, default=1)
    p.add_argument("--tour", choices=["auto", "cp-sat", "gls"], default="auto")
    p.add_argument(
        "--robots", type=int, default=1, help="robots sharing the survey (the slowest first)"
    )
    p.add_argument(
        "--home",
        choices=["origin", "near"],
        default="origin",
        help="where the robots start and end: the Origin's corner, or parked by the locations",
    )
    p.add_argument(
        "--speed", type=float, default=None, help="m/s along routes, for the survey's time"
    )
    p.add_argument(
        "--location-s", type=float, default=None, help="seconds at a location, for its time"
    )
    p.add_argument("--out", type=Path, default=None, help="output folder (runs/plan-FIELD)")
    p.add_argument(
        "--robot", default="", help="robot description: its scanner height (default: Husky)"
    )
    p.add_argument("--remote", action="store_true", help="ask the planner service")
    p.add_argument(
        "--from-survey",
        type=Path,
        default=None,
        metavar="RUN_DIR",
        help="plan on the crop a survey measured (RUN_DIR/crop.json); compares with nominal",
    )
    add_cluster_arguments(p, "the visibility")
    add_connection_arguments(p)
    p.add_argument("--timeout", type=float, default=300.0)


class ProgressBar:
    """A one-line progress bar on a terminal (plain lines elsewhere)."""

    def __init__(self, label: str, stream: TextIO = sys.stderr) -> None:
        self.label, self.stream = label, stream
        self.t0 = time.monotonic()
        self._last = -1

    def __call__(self, done: int, total: int) -> None:
        pct = int(100 * done / max(total, 1))
        if pct == self._last:
            return
        self._last = pct
        bar = "#" * (pct // 4) + "." * (25 - pct // 4)
        end = "\n" if done >= total else ""
        if self.stream.isatty():
            self.stream.write(
                f"\r{self.label} [{bar}] {pct:3d}% {time.monotonic() - self.t0:5.1f} s{end}"
            )
        elif pct % 25 == 0:
            self.stream.write(f"{self.label}: {pct}%\n")
        self.stream.flush()


def survey_line(r: PlanResult) -> str:
    """The survey's estimated time, its swaps and the assumptions it rests on."""
    e, p = r.survey, r.options.pace
    assert e is not None
    swaps = f"{e.swaps} battery swap{'s' if e.swaps != 1 else ''}"
    if e.swaps:
        scans = [r.legs_scan_ids()[k] for k in e.swaps_before]
        swaps += f" (before scans {', '.join(str(i) for i in scans)})"
    line = (
        f"about {e.time_s / 3600:.1f} h, {e.drive_m:.0f} m driven, {swaps}; at "
        f"{p.speed:g} m/s and {p.location_s:g} s a location; {e.battery}"
    )
    if not e.feasible:
        line += "; a location needs more than a full battery above the reserve"
    return line


def fleet_rows(r: PlanResult) -> list[tuple[str, str]]:
    """Each robot's share, and the slowest against one robot alone."""
    f = r.fleet
    assert f is not None
    rows = []
    for part in f.parts:
        e = part.survey
        n = len(part.order) - 2
        rows.append(
            (
                f"robot {part.robot}",
                f"{n} locations, about {e.time_s / 3600:.1f} h, {e.drive_m:.0f} m, "
                f"{e.swaps} swaps, parked at ({part.home[0]:.1f}, {part.home[1]:.1f}): "
                + "-".join("home" if i == 0 else str(i) for i in part.order),
            )
        )
    rows.append(
        (
            "robots",
            f"{len(f.parts)}: the slowest about {f.makespan_s / 3600:.1f} h, "
            f"{f.makespan_s / f.one_robot_s:.2f} x one robot ({f.one_robot_s / 3600:.1f} h); "
            f"split {f.status} in {f.time_s:.1f} s",
        )
    )
    return rows


def summary(r: PlanResult, by_nav: dict[str, float] | None = None) -> str:
    """The plan in a few lines; ``by_nav``: the optimum under each navigation mode
    (:func:`services.planner.compare.lengths_by_nav`), printed when given."""
    c, t, v = r.cover, r.tour, r.visibility
    rows = [
        ("field", f"{r.field}: {len(r.candidates)} candidate locations"),
        (
            "cells",
            f"{c.cells_total} total, {c.cells_coverable} coverable, {c.cells_covered} covered",
        ),
        ("visibility", f"{v.mode}: {v.rays:,} rays, {v.pairs:,} visible pairs, {v.time_s:.3f} s"),
        ("locations", f"{c.count} ({c.method}, {c.status}); greedy {c.greedy_count}"),
        (
            "tour",
            f"{t.nav.upper()} {t.length:.1f} m ({t.method}, {t.status}); "
            f"nearest neighbour {t.nn_length:.1f} m",
        ),
        ("order", "-".join("Origin" if i == 0 else str(i) for i in t.order)),
        ("legs", f"{len(r.legs)} straight legs"),
    ]
    if t.bound is not None and t.bound > 0:
        rows.append(
            (
                "tour bound",
                f"{t.bound:.1f} m (Held-Karp 1-tree): the tour is within "
                f"{t.length / t.bound - 1:.1%} of the shortest",
            )
        )
    if r.survey is not None:
        rows.append(("survey", survey_line(r)))
    if r.fleet is not None:
        rows.extend(fleet_rows(r))
    if by_nav:
        rows.append(
            ("optimum by nav", ", ".join(f"{k.upper()} {v:.1f} m" for k, v in by_nav.items()))
        )
    rows.append(("timings", ", ".join(f"{k} {v:.3f} s" for k, v in r.timings.items())))
    w = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{w}}  {v}" for k, v in rows)


def options(args: argparse.Namespace) -> PlanOptions:
    """The command line's options, checked against their bounds as a request's are
    (a Struct's constructor checks none); ValidationError names the one at fault."""
    pace = {"speed": args.speed, "location_s": args.location_s}
    given = {
        "nav": args.nav,
        "cover": args.cover,
        "visibility": args.visibility,
        "grid_step_deg": args.grid_step,
        "coverage_target": args.coverage,
        "min_hits": args.min_hits,
        "tour": args.tour,
        "robots": args.robots,
        "home": args.home,
        "pace": {k: v for k, v in pace.items() if v is not None},
    }
    return msgspec.convert(given, PlanOptions)


def cmd_plan(args: argparse.Namespace) -> int:
    try:
        opts = options(args)
        robot = load_robot(args.robot)
        dask = bool(args.cluster or args.workers)
        # a Dask worker or a remote planner builds the field from the request alone
        req = request_from_source(args.field, robot, opts, inline=args.remote or dask)
    except (FieldError, ConfigError, msgspec.ValidationError) as exc:
        print(f"phenorover plan: {exc}", file=sys.stderr)
        return 2
    if dask and (args.remote or args.from_survey is not None):
        print("phenorover plan: --cluster and --workers plan one field here", file=sys.stderr)
        return 2
    if args.from_survey is not None:
        return _from_survey(args, req)
    if args.remote:
        from common.client import connect_or_explain
        from common.keys import PLANNER_PLAN
        from common.transport import Bus, RpcError

        prog = "phenorover plan --remote"
        session = connect_or_explain(prog, args.manifest, args.connect, service="planner")
        if session is None:
            return 2  # the line saying which endpoint could not be reached is printed
        with session:
            bus = Bus(session, "cli")
            try:
                result = bus.call(PLANNER_PLAN, req, timeout=args.timeout)
            except RpcError as exc:
                print(f"phenorover plan: {exc}", file=sys.stderr)
                return 1
            finally:
                bus.close()
    else:
        try:
            result = _plan_here(args, req)
        except (FieldError, ValueError, ClusterError) as exc:
            print(f"phenorover plan: {exc}", file=sys.stderr)
            return 2
    print(summary(result, _by_nav(req, result)))
    return _write(args, result)


def _by_nav(req: PlanRequest, result: PlanResult) -> dict[str, float]:
    """The paper's comparison of navigation modes for ``result`` (empty on a field
    this machine cannot read, planned remotely, or too large to compare)."""
    from services.planner.compare import comparable, lengths_by_nav
    from services.planner.request import resolve_field

    if not comparable(result):
        return {}  # before building the field again
    try:
        return lengths_by_nav(resolve_field(req)[1], result)
    except FieldError:
        return {}


def _plan_here(args: argparse.Namespace, req: PlanRequest) -> PlanResult:
    """Plan on this machine, the visibility on a Dask cluster when asked."""
    from services.planner.cluster import DaskChunks
    from services.planner.request import compute

    with cluster_of(args) as cluster:
        chunks = None if cluster is None else DaskChunks(req, cluster)
        return compute(req, progress=ProgressBar("visibility"), chunks=chunks)


def _from_survey(args: argparse.Namespace, req: PlanRequest) -> int:
    """Plan on the measured crop (locally), and on the nominal field to compare."""
    from services.planner.measured import compare, plan_from_survey

    if args.remote:
        print("phenorover plan: --from-survey plans locally; drop --remote", file=sys.stderr)
        return 2
    try:
        nominal, result = plan_from_survey(req, args.from_survey, ProgressBar("visibility"))
    except (FieldError, ValueError) as exc:
        print(f"phenorover plan: {exc}", file=sys.stderr)
        return 2
    print(summary(result))
    print("against the nominal plan of the same field (planned too, for this comparison):")
    print(compare(nominal, result))
    return _write(args, result)


def _write(args: argparse.Namespace, result: PlanResult) -> int:
    out = args.out or Path("runs") / f"plan-{result.field}"
    files = write_all(result, out)
    print("wrote " + ", ".join(str(p) for p in files.values()))
    return 0


def add_command(p: argparse.ArgumentParser) -> None:
    """``phenorover plan``."""
    add_arguments(p)
    p.set_defaults(func=cmd_plan)
