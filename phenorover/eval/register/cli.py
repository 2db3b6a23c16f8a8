"""``phenorover eval register RUN_DIR``: score a registration's outputs against the
simulator's truth and set them beside the paper's figures.

Reads what ``phenorover register`` wrote into RUN_DIR (``report.json``,
``registered.e57``) and the ``<scan>.truth.json`` beside each scan file the report
names (or in ``--scans`` folders), and writes ``eval_register.json`` and
``eval_register.md`` into RUN_DIR (or ``--out``). ``truth`` is null when no scan has a
truth file (a real survey): the paper comparison is still written. Lengths in
``truth`` are metres (the registration report's units), in ``paper`` centimetres.
Bad input is one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from common.files import finite, write_atomic
from common.pointcloud import read_e57
from common.poses import F64, PoseError, check_pose
from phenorover.eval.register.paper import compare
from phenorover.eval.register.score import METHODS, ScanEvidence, TruthScore, score
from phenorover.eval.register.truth import find_truth, true_pose

Json = dict[str, Any]
SCHEMA = "phenorover.eval.register/1"
JSON_NAME, MD_NAME = "eval_register.json", "eval_register.md"
# method -> its per-scan pose in report.json's registration_detail.scans
POSE_KEYS = {
    "navigation": "nav_pose",
    "c2c": "c2c_pose",
    "c2c_without_targets": "c2c_without_targets_pose",
    "target_based": "target_pose",
}


class EvalError(ValueError):
    """The outputs cannot be scored; the message names the file and the cause."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run_dir", type=Path, help="where phenorover register wrote its outputs")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: RUN_DIR)")
    p.add_argument(
        "--scans",
        type=Path,
        action="append",
        default=[],
        metavar="DIR",
        help="where to look for truth files missing beside the scans (repeatable)",
    )
    p.add_argument("--sample-points", type=int, default=5000, help="per scan, for point errors")
    p.add_argument("--seed", type=int, default=0)


def _load_report(run_dir: Path) -> Json:
    path = run_dir / "report.json"
    try:
        rep: Json = json.loads(path.read_text())
    except FileNotFoundError:
        raise EvalError(f"{path}: no registration report (run phenorover register first)") from None
    except (OSError, ValueError) as exc:
        raise EvalError(f"{path}: not a readable report: {exc}") from None
    return rep


def _pose(m: Any, what: str) -> F64:
    try:
        return check_pose(np.asarray(m, dtype=np.float64), what)
    except (PoseError, ValueError, TypeError) as exc:
        raise EvalError(str(exc)) from None


def score_outputs(
    run_dir: Path, scan_dirs: list[Path], sample_points: int = 5000, seed: int = 0
) -> tuple[Json, TruthScore | None]:
    """(the registration report, its score against the truth or None when no scan has
    a truth file). Raises EvalError."""
    rep = _load_report(run_dir)
    detail = rep.get("registration_detail")
    if not detail:
        return rep, None
    where = run_dir / "report.json"
    rows: list[Json] = detail["scans"]
    truths = [find_truth(r.get("file", ""), scan_dirs) if r.get("file") else None for r in rows]
    if all(t is None for t in truths):
        return rep, None
    missing = [r["name"] for r, t in zip(rows, truths, strict=True) if t is None]
    if missing:
        raise EvalError(f"no truth file for scans {missing} (looked beside their files)")
    e57 = run_dir / (rep.get("outputs") or {}).get("e57", "registered.e57")
    try:
        clouds = {s.name: s for s in read_e57(e57)}
    except ValueError as exc:
        raise EvalError(str(exc)) from None
    scans: list[ScanEvidence] = []
    trues: list[F64] = []
    # a method is scored when every scan has its pose
    poses: dict[str, list[F64]] = {
        m: [] for m, key in POSE_KEYS.items() if all(r.get(key) is not None for r in rows)
    }
    for r, t in zip(rows, truths, strict=True):
        name = r["name"]
        if name not in clouds:
            raise EvalError(f"{e57}: has no scan {name!r} (the report lists it)")
        centres = np.asarray(r.get("sphere_centres", []), dtype=np.float64).reshape(-1, 3)
        labels = np.asarray(r.get("sphere_targets", []), dtype=np.int64)
        if len(labels) != len(centres):
            raise EvalError(f"{where}: scan {name}: {len(centres)} spheres, {len(labels)} labels")
        scans.append(ScanEvidence(clouds[name].points, centres, labels))
        for m, ps in poses.items():
            ps.append(_pose(r[POSE_KEYS[m]], f"{where}: {name} {POSE_KEYS[m]}"))
        assert t is not None
        trues.append(true_pose(t, f"truth of {name}"))
    return rep, score(scans, poses, trues, sample_points, seed)


def _cm(v: float | None, digits: int = 2) -> str:
    return "–" if v is None or not math.isfinite(v) else f"{100 * v:.{digits}f}"


def _c(v: float | None) -> str:
    return "–" if v is None else f"{v:.2f}"


def markdown(result: Json, truth: TruthScore | None) -> str:
    lines = [f"# Registration evaluation: {result['mission']}", ""]
    lines += ["## Against the simulator's truth", ""]
    if truth is None:
        lines.append("No scan has a truth file (a real survey): nothing to score.")
    else:
        lines += [
            f"{truth.scans} scans, {truth.targets} targets with a true position (cm).",
            "",
            "| method | target mean | horizontal | vertical | max | max point error "
            "| mean point error |",
            "|---|---|---|---|---|---|---|",
        ]
        for key, label in METHODS:
            m = truth.methods.get(key)
            if m is None:
                continue
            t, p = m.targets, m.points
            lines.append(
                f"| {label} | {_cm(t.mean)} | {_cm(t.horizontal)} | {_cm(t.vertical)} "
                f"| {_cm(t.max)} | {_cm(p.max)} | {_cm(p.mean)} |"
            )
    paper = result["paper"]
    lines += ["", "## Beside the paper (ENGR, FARO SCENE; cm)", ""]
    if paper is None:
        lines.append("The report has no registration.")
        return "\n".join(lines) + "\n"
    lines += [
        "Ours / the paper's Table 1 (targets: against the target-based reference; "
        "points: scan point statistics, the overlap residuals SCENE reports):",
        "",
        "| method | target mean | horizontal | vertical | max point error | mean point error |",
        "|---|---|---|---|---|---|",
    ]
    cols = (
        "target_mean_cm",
        "target_horizontal_cm",
        "target_vertical_cm",
        "max_point_cm",
        "mean_point_cm",
    )
    for row in paper["table1"]:
        cells = [f"{_c(row['ours'][c])} / {_c(row['paper'][c])}" for c in cols]
        lines.append(f"| {row['label']} | " + " | ".join(cells) + " |")
    h = paper["hausdorff"]
    ours = h["ours"]
    lines += ["", "Nav. sensors + C2C cloud to the target-based cloud:", ""]
    lines.append(
        "ours "
        + (
            "–"
            if ours is None
            else f"{_c(ours['mean_cm'])} cm mean, SD {_c(ours['sd_cm'])} cm, "
            f"{ours['below_2cm']:.0%} < 2 cm, {ours['below_3cm']:.0%} < 3 cm"
        )
        + f"; paper {h['paper']['mean_cm']} cm mean, SD {h['paper']['sd_cm']} cm, "
        f"{h['paper']['below_2cm']:.0%} < 2 cm, {h['paper']['below_3cm']:.0%} < 3 cm."
    )
    lines += [
        "",
        "The paper's target statistics are SCENE's sphere residuals, ours the sphere "
        "centres placed by each method against the target-based positions: only the "
        "point statistics compare like for like.",
    ]
    return "\n".join(lines) + "\n"


def evaluate(
    run_dir: Path,
    out: Path | None = None,
    scan_dirs: list[Path] | None = None,
    sample_points: int = 5000,
    seed: int = 0,
) -> tuple[Json, TruthScore | None]:
    """Score RUN_DIR's registration and write ``eval_register.json`` and ``.md`` into
    ``out`` (default RUN_DIR), each whole or not at all. Raises EvalError or OSError."""
    rep, truth = score_outputs(run_dir, scan_dirs or [], sample_points, seed)
    mission = (rep.get("navigation") or {}).get("mission", "")
    result: Json = {
        "schema": SCHEMA,
        "mission": mission,
        "truth": None if truth is None else msgspec.to_builtins(truth),
        "paper": compare(rep.get("registration")),
    }
    dest = out or run_dir
    dest.mkdir(parents=True, exist_ok=True)
    write_atomic(dest / JSON_NAME, json.dumps(finite(result), indent=1, allow_nan=False).encode())
    write_atomic(dest / MD_NAME, markdown(result, truth).encode())
    return result, truth


def run(args: argparse.Namespace) -> int:
    """``phenorover eval register``: 0 when written, 2 on bad input (one line)."""
    try:
        _, truth = evaluate(args.run_dir, args.out, args.scans, args.sample_points, args.seed)
    except (EvalError, ValueError, OSError) as exc:
        print(f"phenorover eval register: {exc}", file=sys.stderr)
        return 2
    dest = (args.out or args.run_dir) / MD_NAME
    if truth is None:
        print(f"no truth files (a real survey): paper comparison only: {dest}", flush=True)
    else:
        c2c = truth.methods["c2c"].points.mean
        print(f"nav + C2C mean point error vs truth {_cm(c2c)} cm: {dest}", flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m phenorover.eval.register", description=__doc__)
    add_arguments(p)
    return run(p.parse_args(argv))
