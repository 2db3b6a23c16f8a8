"""Whole-survey benchmark: the ENGR survey of ``make sim`` (deploy/sim.toml: the
simulated devices' backends), of ``make hil`` (deploy/hil.toml: the hardware
backends against the simulated devices on their own wires) and of ``make sim`` with
the paper's method (``paper``: deploy/sim.toml under the navigation profile of
:mod:`phenorover.eval.profiles`, the baseline), one after the other, each scored
against the simulator's truth with ``phenorover eval register``. ``sim`` and
``paper`` run once per seed (``--seeds``: another draw of the simulator's noise and
the receivers' errors, :func:`phenorover.eval.profiles.seeded`) and report the mean
over the seeds with each seed's value beside it; ``hil`` runs its manifest's draw.

Figures are reported, never asserted. Per manifest: locations scanned, the wall
time of the whole command (services up, plan, survey, registration), the distance
driven as measured, and the registration's mean point error against the truth (the
headline; target 1.0 cm). A survey that does not end with every location scanned is
a failed experiment (exit 1).

The baseline's survey is set beside the paper's registration figures (the
pre-alignment's largest mismatch, 27.3 cm; the scan point statistics SCENE gave,
2.07 cm mean point error between overlapping scans for nav + C2C and 1.37 cm for
the target-based registration, which are overlap residuals, not errors against a
truth; the nav + C2C cloud against the target-based one, 1.25 cm mean and 0.82 cm
SD), and ours against the baseline's (nav + C2C at most half of it, against the
truth).

    python tests/bench/bench_survey.py [--json OUT] [--only sim hil paper] [--seeds 1 2 3] [--keep]

``--keep`` carries the figures of the surveys not run from the ``--json`` file (each
keeps its own date and commit), so one survey can be run again alone.
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import tomli_w

from common.config import ConfigError, load_manifest, read_toml
from phenorover.eval import profiles
from phenorover.eval.error_models import from_manifest
from phenorover.eval.register.paper import HAUSDORFF, TABLE1
from phenorover.eval.results import Bench, Goal, spread
from tests.bench.survey_compare import (
    COMPARISONS,
    PRE_ALIGNMENT_MAX_CM,
    compare,
)
from tests.bench.survey_pace import pace_figures, reference_model, survey_pace

REPO = Path(__file__).resolve().parents[2]
# name -> (manifest, navigation profile, field: None for the manifest's)
SURVEYS: dict[str, tuple[Path, str, str | None]] = {
    "sim": (REPO / "deploy" / "sim.toml", "ours", None),
    "spl": (REPO / "deploy" / "sim.toml", "ours", "spl"),
    "hil": (REPO / "deploy" / "hil.toml", "ours", None),
    "paper": (REPO / "deploy" / "sim.toml", "paper", None),
}
SUMMARY = re.compile(
    r"summary: .*?(\d+)/(\d+) scans done, (\d+) failed, ([\d.]+) m driven.*?; wall (\d+) s; "
    r"files in (\S+)"
)
# the pace issue's: make sim (this bench's "sim" survey, deploy/sim.toml) within 150 s
MAKE_SIM_WALL = Goal(
    "<=",
    150.0,
    "the services' CPU per simulated second (cpu.json, per service below) on two cores, "
    "or a shorter survey in simulated time (field time per location)",
)
POINT_ERROR = Goal(
    "<=",
    1.0,
    "the scans that see no sphere and pair with no neighbour keep their navigation pose, "
    "whose heading is the compass under the crop (about 2 deg a fix) averaged over the scan, "
    "worth a centimetre at 15 m: a longer stand before the scan, or more spheres",
)


def survey(manifest: Path) -> tuple[dict[str, Any], str]:
    """Run ``phenorover sim`` on ``manifest``: its summary figures, or why it failed;
    its output goes to ``sim.log`` in the survey's run folder."""
    t0 = time.monotonic()
    r = subprocess.run(
        [sys.executable, "-m", "phenorover", "sim", "--manifest", str(manifest)],
        capture_output=True,
        text=True,
        cwd=REPO,
    )
    wall = time.monotonic() - t0
    m = SUMMARY.search(r.stdout)
    if m is None:
        last = (r.stderr.strip() or r.stdout.strip() or "no output").splitlines()[-1]
        return {"wall_s": wall}, f"phenorover sim exited {r.returncode}: {last[:300]}"
    done, total, failed, driven, _, run = m.groups()
    stats = {
        "scanned": int(done),
        "total": int(total),
        "failed": int(failed),
        "driven_m": float(driven),
        "wall_s": wall,
        "run_dir": str(REPO / run),
    }
    # the services' logs beside the survey's files (each arrival's settle, say)
    (REPO / run / "sim.log").write_text(r.stdout + r.stderr)
    if r.returncode != 0:
        said = [ln for ln in r.stdout.splitlines() if "not scanned" in ln or "failed" in ln]
        last = (said or r.stderr.strip().splitlines() or ["no output"])[-1]
        return stats, f"phenorover sim exited {r.returncode}: {last.strip()[:300]}"
    return stats, ""


def registration(run_dir: Path) -> tuple[dict[str, float], str]:
    """``phenorover eval register`` on a survey: its figures against the truth (cm):
    ``c2c`` (nav + C2C mean point error), ``plain`` (the same without the spheres in
    the pose graph, the clouds alone; ``c2c`` when it had none), ``nav`` and
    ``nav_max`` (navigation alone, the pre-alignment: mean and largest point error),
    ``hausdorff_mean`` and ``hausdorff_sd`` (the nav + C2C cloud against the
    target-based one); or why not."""
    r = subprocess.run(
        [sys.executable, "-m", "phenorover", "eval", "register", str(run_dir)],
        capture_output=True,
        text=True,
        cwd=REPO,
    )
    path = run_dir / "eval_register.json"
    if r.returncode != 0 or not path.exists():
        return {}, f"eval register exited {r.returncode}: {r.stderr.strip()[-300:]}"
    report = json.loads(path.read_text())
    truth = report.get("truth")
    if not truth:
        return {}, "no truth files beside the scans"
    methods = truth["methods"]
    plain = methods.get("c2c_without_targets", methods["c2c"])
    out = {
        "c2c": 100.0 * float(methods["c2c"]["points"]["mean"]),
        "plain": 100.0 * float(plain["points"]["mean"]),
        "nav": 100.0 * float(methods["navigation"]["points"]["mean"]),
        "nav_max": 100.0 * float(methods["navigation"]["points"]["max"]),
    }
    # SCENE's scan point statistics, as the paper's Table 1 gives them (overlap residuals)
    for row in (report.get("paper") or {}).get("table1", []):
        for key in ("mean_point_cm", "max_point_cm"):
            if row["ours"].get(key) is not None:
                out[f"overlap_{key.split('_')[0]}_{row['method']}"] = float(row["ours"][key])
    h = ((report.get("paper") or {}).get("hausdorff") or {}).get("ours") or {}
    for key in ("mean", "sd"):
        if h.get(f"{key}_cm") is not None:
            out[f"hausdorff_{key}"] = float(h[f"{key}_cm"])
    return out, ""


def survey_manifest(
    manifest: Path, profile: str, seed: int | None, tmp: Path, field: str | None = None
) -> Path:
    """``manifest`` with navigation ``profile``'s settings over its own and, with
    ``seed``, another draw of the simulator's and receivers' noise, and ``field`` (a
    file in ``tmp``). The mission never resumes: a survey an interrupted benchmark left
    unfinished in the run folder would otherwise be finished and scored as this one."""
    m = profiles.apply(read_toml(manifest), profile)
    m["services"].setdefault("mission", {})["resume"] = False
    if seed is not None:
        m = profiles.seeded(m, seed)
    if field is not None:
        m["field"] = field
    path = tmp / f"{manifest.stem}-{profile}-{seed}.toml"
    path.write_text(tomli_w.dumps(m))
    return path


def title(name: str, manifest: Path) -> str:
    """How survey ``name``'s figures are named (their common beginning)."""
    what = {
        "paper": "make sim with the paper's method",
        "spl": "phenorover sim --field spl",
    }.get(name, f"make {name}")
    return f"{what} ({manifest.name})"


def carry(
    bench: Bench, path: Path, names: list[str], comparisons: bool
) -> dict[str, dict[str, Any]]:
    """The figures and details of surveys ``names`` from an earlier results file,
    each figure with its own date and commit (``--keep``), with ``comparisons`` the
    figures that compare them too; nothing when the file is missing or unreadable."""
    prefixes = [title(n, SURVEYS[n][0]) + "," for n in names]
    old = bench.carry(path, prefixes + (list(COMPARISONS) if comparisons else []))
    return {} if old is None else {n: old.details[n] for n in names if n in old.details}


def one_survey(
    manifest: Path, profile: str, seed: int | None, field: str | None = None
) -> dict[str, Any]:
    """One survey and its scoring: its figures (see :func:`registration` and
    :func:`survey_pace`), its true stops and ``failed`` (why not, or empty)."""
    with tempfile.TemporaryDirectory() as tmp:
        path = survey_manifest(manifest, profile, seed, Path(tmp), field)
        stats, why = survey(path)
        model = reference_model(path)
    print(f"{profile} seed {seed}: {why or json.dumps(stats)}", flush=True)
    reg, reg_why = ({}, why) if why else registration(Path(stats["run_dir"]))
    run_dir = Path(stats["run_dir"]) if not why and "run_dir" in stats else None
    paced = survey_pace(run_dir, model) if run_dir else {}
    return {
        **stats,
        **reg,
        **paced,
        "seed": seed,
        "failed": why or reg_why,
    }


def measure(
    bench: Bench,
    name: str,
    manifest: Path,
    profile: str,
    seeds: list[int] | None,
    field_name: str | None = None,
) -> dict[str, Any]:
    """The surveys on ``manifest`` under navigation ``profile``, one per seed (the
    manifest's own draw when ``seeds`` is None), and their figures: each the mean over
    the seeds that gave it, the seeds' values beside it. What they measured, for the
    details: the means, and ``runs`` per seed."""
    try:
        models = from_manifest(manifest)
        field = field_name or load_manifest(manifest).field
        model = reference_model(manifest)
    except ConfigError as exc:
        bench.fail(name, str(exc))
        return {"failed": str(exc)}
    draws: list[int | None] = list(seeds) if seeds else [None]
    runs = [one_survey(manifest, profile, seed, field_name) for seed in draws]
    for r in runs:
        if r["failed"]:
            bench.fail(f"{name} seed {r['seed']}", r["failed"])
    what = f"{title(name, manifest)}, field {field}"
    if seeds:
        models = {**models, "seeds": f"surveys with seeds {', '.join(map(str, seeds))}"}
    baseline = profile == "paper"
    means: dict[str, Any] = {}

    def fig(label: str, key: str, unit: str, note: str = "", **kw: Any) -> None:
        vals = [float(r[key]) for r in runs if not r["failed"] and r.get(key) is not None]
        value = statistics.mean(vals) if vals else None
        if value is not None:
            means[key] = value
        note = "; ".join(n for n in (note, spread(vals)) if n)
        why = "; ".join(r["failed"] for r in runs if r["failed"]) or "no survey measured it"
        bench.figure(
            f"{what}: {label}", value, unit, missing=why, error_models=models, note=note, **kw
        )

    fig("locations scanned", "scanned", "", note=f"of {runs[0].get('total')}")
    fig(
        "wall time, services up to registration done",
        "wall_s",
        "s",
        goal=MAKE_SIM_WALL if name == "sim" else None,
    )
    fig("distance driven (measured, odometry)", "driven_m", "m")
    fig(
        "nav + C2C: mean point error against the truth",
        "c2c",
        "cm",
        note="the clouds alone, as the paper's C2C" if baseline else "spheres in the pose graph",
        goal=None if baseline else POINT_ERROR,
        headline=True,
    )
    if not baseline:
        fig("nav + C2C, the clouds alone: mean point error against the truth", "plain", "cm")
    for method, label in (("c2c", "nav + C2C"), ("target_based", "target-based")):
        for key in ("mean", "max"):
            fig(
                f"{label}: {key} point error between overlapping scans (SCENE's scan point "
                "statistics, the paper's metric; no truth)",
                f"overlap_{key}_{method}",
                "cm",
                paper=TABLE1[method][f"{key}_point_cm"] if baseline else None,
            )
    fig("navigation alone (pre-alignment): mean point error against the truth", "nav", "cm")
    fig(
        "navigation alone (pre-alignment): largest point error against the truth",
        "nav_max",
        "cm",
        paper=PRE_ALIGNMENT_MAX_CM if baseline else None,
    )
    for key, label in (("mean", "mean"), ("sd", "SD")):
        fig(
            f"nav + C2C cloud against the target-based cloud: {label} distance",
            f"hausdorff_{key}",
            "cm",
            paper=HAUSDORFF[f"{key}_cm"] if baseline else None,
        )
    pace_figures(fig, baseline, model, runs)
    return {**means, "runs": runs}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--only", nargs="+", choices=sorted(SURVEYS), default=sorted(SURVEYS))
    ap.add_argument(
        "--seeds",
        type=int,
        nargs="+",
        default=[1, 2, 3],
        help="one survey per seed for sim, spl and paper (hil: its manifest's draw, once)",
    )
    ap.add_argument(
        "--keep",
        action="store_true",
        help="the surveys not run keep their figures from the --json file",
    )
    args = ap.parse_args()
    bench = Bench("bench_survey")
    details = {
        name: measure(bench, name, manifest, profile, None if name == "hil" else args.seeds, field)
        for name, (manifest, profile, field) in SURVEYS.items()
        if name in args.only
    }
    # comparisons of surveys that were all kept are kept too, with the date and
    # commit they were measured at, not computed again under this run's
    compared = "sim" in args.only or "paper" in args.only
    if args.keep and args.json is not None:
        kept = [n for n in SURVEYS if n not in args.only]
        details |= carry(bench, args.json, kept, comparisons=not compared)
    if compared or not args.keep:
        compare(bench, details)
    return bench.finish(args.json, details)


if __name__ == "__main__":
    sys.exit(main())
