"""Navigation benchmark: the paper's three experiments (``phenorover nav-test``) on the
simulated ENGR field with the default error models. Figures are reported, never
asserted, through phenorover.eval.results; an experiment that fails makes it exit 1.

In simulation the headline is the true figure. Border and serpentine: the true pose's
cross-track error against the leg being followed (targets: border mean <= 2.0 cm and
>= 90 % below 5 cm; serpentine mean <= 3.0 cm). Stationary: where the robot truly
stands against the planned point (within the mission's 5 cm arrival tolerance: a scan
location is reached to centimetres, docs/navigation.md) and the estimate's heading
against the true heading over the hold (<= 0.1 deg); the paper's metric, the estimate
against the plan, is reported beside it with no target, since the fine positioning
moves until the estimate is within its own tolerances. Distances driven are measured
(the true path), beside the planned route's length.

The world runs in lockstep with the services (``--rtf`` its cap), so the same seed
gives the same figures on a busy machine; ``--free`` runs it beside them.
``--experiments`` runs some alone; with ``--keep`` the others keep their figures from
the ``--json`` file (each with its own date and commit).

    python tests/bench/bench_nav.py [--json OUT] [--rtf 1000] [--free]
        [--experiments border serpentine stationary] [--keep]
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from common.config import ConfigError
from phenorover.eval.error_models import from_manifest
from phenorover.eval.results import Bench, Goal
from tests.bench.survey_pace import TRUE_STOP

REPO = Path(__file__).resolve().parents[2]
EXPERIMENTS = ("border", "serpentine", "stationary")
CORNERS = (
    "a tracker that closes the corner turn's sideways shift faster (yaw-rate feedback, "
    "a regulated look-ahead), and a filter that averages the crop's correlated fix noise "
    "while driving without lagging the loose ground's slip"
)
GOALS = {
    "border_xte": Goal("<=", 2.0, CORNERS),
    "border_below": Goal(">=", 90.0, CORNERS),
    "serpentine_xte": Goal("<=", 3.0, CORNERS),
    "stop": TRUE_STOP,
    "heading": Goal(
        "<=",
        0.1,
        "a heading reference that the crop does not blur: under the plants the compass "
        "reads about 2 deg per fix, correlated over seconds, and a hold averages only so "
        "many of them; the scan against its neighbours (registration) or the lidar's "
        "view of the plot edges would give the heading independently",
    ),
}
BY_CONSTRUCTION = (
    "no target: the fine phase places the estimate of its moment within its tolerances "
    "(fine_tolerance_m along the leg, reapproach_tolerance_m across it); over the hold "
    "the estimate moves to where the robot stands"
)


def run_experiment(
    exp: str,
    rtf: float,
    out: Path,
    profile: str = "ours",
    seed: int | None = None,
    lockstep: bool = False,
) -> tuple[dict[str, Any] | None, str]:
    """The experiment's stats.json, or None and why it failed. ``lockstep``: the world
    in lockstep with the services (``rtf`` its cap), so a seed gives the same run."""
    cmd = [sys.executable, "-m", "phenorover", "--log-level", "warning", "nav-test", exp]
    cmd += ["--rtf", str(rtf), "--out", str(out), "--profile", profile]
    cmd += ["--lockstep"] if lockstep else []
    if seed is not None:
        cmd += ["--seed", str(seed)]
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO)
    stats = out / "stats.json"
    if r.returncode != 0 or not stats.exists():
        last = (r.stderr.strip() or r.stdout.strip() or "no output").splitlines()[-1]
        return None, f"nav-test {exp} exited {r.returncode}: {last[:300]}"
    data: dict[str, Any] = json.loads(stats.read_text())
    if data.get("result", "arrived") != "arrived":
        return data, f"the route ended {data['result']}, not arrived"
    return data, ""


def models(out: Path) -> dict[str, str]:
    """The error models of the experiment's effective manifest (deploy/sim.toml's when
    the experiment wrote none)."""
    try:
        return from_manifest(out / "manifest.toml")
    except (ConfigError, OSError):
        return from_manifest(REPO / "deploy" / "sim.toml")


def record(bench: Bench, exp: str, s: dict[str, Any] | None, why: str) -> None:
    """The experiment's figures; with ``why`` (it failed) every one is unmeasured."""

    def get(*path: str, scale: float = 1.0) -> float | None:
        v: Any = s
        for k in path:
            v = v.get(k) if isinstance(v, dict) else None
        return None if why or not isinstance(v, int | float) else scale * v

    def fig(name: str, value: float | None, unit: str, **kw: Any) -> None:
        bench.figure(f"{exp}: {name}", value, unit, missing=why or "not in stats.json", **kw)

    if exp in ("border", "serpentine"):
        fig(
            "mean cross-track error, true pose against the leg",
            get("xte_mean_cm"),
            "cm",
            goal=GOALS[f"{exp}_xte"],
            headline=True,
            paper=2.37 if exp == "border" else 3.67,
        )
        below = {"goal": GOALS["border_below"], "headline": True, "paper": 86.0}
        fig(
            "share of the path below 5 cm",
            get("share_below_5cm", scale=100),
            "%",
            **(below if exp == "border" else {}),
        )
        fig("share of the path above 10 cm", get("share_above_10cm", scale=100), "%")
        fig("max cross-track error", get("xte_max_cm"), "cm")
        fig("heading error SD, true pose against the leg", get("heading_sd_deg"), "deg")
        fig("distance driven, the true path", get("driven_true_m"), "m")
        fig("route length, planned", get("planned_route_m"), "m", note="planned, not measured")
        return
    fig(
        "true stop against the planned point, mean distance over the hold",
        get("true_stop_to_planned_cm"),
        "cm",
        goal=GOALS["stop"],
        headline=True,
    )
    fig(
        "estimate against the planned point, mean distance (the paper's metric)",
        get("paper_estimate_to_planned_cm"),
        "cm",
        note=BY_CONSTRUCTION + "; paper 0.57 / 0.38 cm",
    )
    fig(
        "true heading against the leg's heading, mean magnitude",
        get("true_heading_to_planned_deg"),
        "deg",
        note=(
            "no target: a scan location plans no heading (the scanner sees 360 deg); the "
            "robot keeps the heading it came in with, within heading_tolerance_deg"
        ),
    )
    herr = get("estimate_heading_error_deg")
    fig(
        "estimate's heading against the true heading, mean over the hold",
        None if herr is None else abs(herr),
        "deg",
        goal=GOALS["heading"],
        headline=True,
        note="what a scan's placement inherits: 0.1 deg is 1.7 cm at 10 m",
    )
    fig(
        "estimate's heading residual about the held heading, mean magnitude (the paper's metric)",
        get("paper_heading_residual_deg"),
        "deg",
        paper=0.035,
    )
    ex, ey = get("estimate_error_cm", "x"), get("estimate_error_cm", "y")
    fig(
        "estimate against the truth, horizontal (mean over the hold)",
        None if ex is None or ey is None else math.hypot(ex, ey),
        "cm",
        note=(
            "what the tilt correction leaves (the IMU's bias as the turns on the way "
            "levelled it) and the crop's fix noise averaged over the hold"
        ),
    )
    fig("estimate against the truth, vertical", get("estimate_error_cm", "z"), "cm")
    fig("estimate's position residual SD, x", get("estimate", "residual_x_sd_cm"), "cm")
    fig("estimate's position residual SD, y", get("estimate", "residual_y_sd_cm"), "cm")
    fig("time held", get("hold_s"), "s")


def add_arguments(ap: argparse.ArgumentParser) -> None:
    """The options of a benchmark of nav-test's experiments (this one and
    bench_profiles): its output, the world's pace, which experiments, what is kept."""
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--rtf", type=float, default=1000.0, help="the world's pace (in lockstep: cap)")
    ap.add_argument("--free", action="store_true", help="the world beside the services")
    ap.add_argument("--experiments", nargs="+", choices=EXPERIMENTS, default=list(EXPERIMENTS))
    ap.add_argument(
        "--keep",
        action="store_true",
        help="the experiments not run keep their figures from the --json file",
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_arguments(ap)
    args = ap.parse_args()
    bench = Bench("bench_nav")
    details: dict[str, Any] = {}
    if args.keep and args.json is not None:
        kept = [e for e in EXPERIMENTS if e not in args.experiments]
        old = bench.carry(args.json, [f"{e}:" for e in kept])
        details |= {e: old.details[e] for e in kept if old is not None and e in old.details}
    with tempfile.TemporaryDirectory() as d:
        for exp in args.experiments:
            out = Path(d) / exp
            stats, why = run_experiment(exp, args.rtf, out, lockstep=not args.free)
            print(f"{exp}: {why or json.dumps(stats)}", flush=True)
            if why:
                bench.fail(exp, why)
            details[exp] = stats if stats is not None else {"failed": why}
            bench.error_models = models(out)
            record(bench, exp, stats, why)
    return bench.finish(args.json, details)


if __name__ == "__main__":
    sys.exit(main())
