"""Traits benchmark: ``python tests/bench/bench_traits.py [--json out.json]``.

The example trial (``common/fields/trial.toml``: ENGR's 60 plots, 20 entries x 3
reps) grown by the simulator (:mod:`services.sim.trial`) and surveyed as the
registration benchmark does it (:func:`bench_registration.survey`: a plan's
locations, a FARO scan at 0.36 deg from each, navigation poses drawn under its error
model, then registration: nav + C2C with the spheres) on two dates, as a user flies a
season: the first on the plan on the nominal boxes, the second on the plan made from
the first's crop (``phenorover plan --from-survey``); beside it, like for like, the
second date flown on the nominal plan as well. Then the
traits (:mod:`services.traits`) of the registered cloud, merged at 1 cm as
``registered.laz`` is, scored against the same definitions applied to the simulator's
plants (:func:`services.sim.plant_truth.plant_truth`):

- per seed (three) and two dates (70 and 91 days after planting): canopy height
  RMSE and bias, cover and voxel volume errors, growth in height between the dates,
  heritability of height measured against the same statistic on the true heights;
  the same for the second date on the nominal plan;
- the plan from the survey against the nominal one: the true foliage cells each
  plan's scans see at 91 days, and their locations and tours (seed 1);
- ``phenorover traits`` wall time on one survey (a run folder, the command as a
  user runs it) and on a season of five dates (one seed).

Figures are reported, never asserted; an experiment that fails makes it exit 1.
"""

from __future__ import annotations

import argparse
import datetime
import logging
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
os.environ.setdefault("NUMBA_CACHE_DIR", str(Path(__file__).resolve().parents[2] / ".cache/numba"))

from common import fieldbook
from common.field import load_field
from common.messages.plan import PlanResult
from common.pointcloud import voxel_merge, write_e57, write_merged_laz
from phenorover.eval import traits as ev
from phenorover.eval import traits_bench as fig
from phenorover.eval.registration import NAV_SIGMA
from phenorover.eval.results import Bench
from services.mission.log import MissionLog
from services.planner.core import plan
from services.register.pipeline import register
from services.sim.plant_config import FoliageConfig, TrialConfig
from services.sim.plant_truth import plant_truth
from services.sim.render import ScanSettings
from services.sim.world import World
from services.sim.world_config import WorldConfig
from services.traits.compute import RunTraits, compute_traits
from services.traits.config import TraitsConfig
from services.traits.run import RunInput
from services.traits.series import season
from services.traits.stats import heritability
from tests.bench.bench_registration import config as register_config
from tests.bench.bench_registration import survey

SEEDS = (1, 2, 3)
PLANTED = datetime.date(2026, 5, 1)  # the trial's planting_date
DATES = (datetime.date(2026, 7, 10), datetime.date(2026, 7, 31))  # 70 and 91 days
SEASON = (datetime.date(2026, 6, 20), datetime.date(2026, 7, 1), datetime.date(2026, 7, 20))


# the simulated plants' voxel (``--foliage-voxel``; the simulator's default otherwise)
FOLIAGE = FoliageConfig()


def world_config(seed: int, date: datetime.date) -> WorldConfig:
    return WorldConfig(seed=seed, trial=TrialConfig(date=date), foliage=FOLIAGE)


def simulate(
    seed: int,
    date: datetime.date,
    xy: list[Any],
    pr: PlanResult,
    runs: Path,
    step: float,
    plan: str = "",
) -> tuple[RunTraits, list[dict[str, Any]], float]:
    """One survey of the trial on ``date`` from the locations ``xy`` of the plan ``pr``:
    its measured traits, the plants' truth and the registration's time; the run folder
    (``mission.db``, ``registered.laz``; its name ends in ``plan``) is left in
    ``runs`` for the command-line timings."""
    layout, field = load_field("trial")
    world = World(layout, field, world_config(seed, date))
    truth = plant_truth(layout, field, world.terrain, world.foliage, world.trial)
    run = runs / _run_name(seed, date, plan)
    run.mkdir(parents=True)
    rng = np.random.default_rng([seed, date.toordinal()])
    inputs, _ = survey(world, xy, run, ScanSettings(step_deg=step), rng)
    t = time.perf_counter()
    reg = register(inputs, register_config())
    reg_s = time.perf_counter() - t
    merged = voxel_merge(reg.scans, 0.01)
    pts, src = merged[0], merged[2]
    write_merged_laz(run / "registered.laz", merged)
    # the scans with their poses, as `phenorover register` leaves them: where each
    # point was seen from, for the voxel volume's hidden voxels
    write_e57(run / "registered.e57", reg.scans)
    # as a simulated mission's folder holds it: the simulator's clock has no calendar,
    # so the traits take the survey's date from the manifest's trial
    (run / "manifest.toml").write_text(
        f'machine = "bench"\n[services.sim.world.trial]\ndate = {date.isoformat()}\n'
    )
    log = MissionLog(run / "mission.db")
    log.create(run.name, pr.field, 0, msgspec.json.encode(pr).decode(), [])
    log.set_state("done")
    log.close()
    inp = RunInput(
        run_dir=run,
        mission={"id": run.name},
        layout=layout,
        field=field,
        records=fieldbook.records(layout, field),
        date=date.isoformat(),
        date_source="the benchmark",
        cloud=pts,
        source=src,
    )
    return compute_traits(inp, TraitsConfig()), truth, reg_s


def _cli_time(runs: list[Path]) -> float:
    """Wall seconds of ``python -m services.traits RUNS...`` as a user runs it."""
    cmd = [sys.executable, "-m", "services.traits", *map(str, runs)]
    t = time.perf_counter()
    # ten times the season's target: a command that hangs fails the experiment
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=10 * fig.TARGETS["season_s"])
    took = time.perf_counter() - t
    if r.returncode != 0:
        raise RuntimeError(f"phenorover traits exited {r.returncode}: {r.stderr.strip()[-300:]}")
    return took


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path, help="write the figures as JSON here")
    ap.add_argument("--step", type=float, default=0.36, help="scan step (deg)")
    ap.add_argument("--seeds", type=int, nargs="+", default=list(SEEDS))
    ap.add_argument("--no-timings", action="store_true", help="skip the command's timings")
    ap.add_argument("--keep", type=Path, default=None, help="keep the run folders here")
    ap.add_argument(
        "--foliage-voxel", type=float, default=None, metavar="M", help="the plants' voxel (m)"
    )
    ap.add_argument("-v", "--verbose", action="store_true")
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING)
    if args.foliage_voxel is not None:
        global FOLIAGE
        FOLIAGE = FoliageConfig(voxel=args.foliage_voxel)
    bench = Bench(
        "bench_traits", fig.error_models(args.step, NAV_SIGMA, TrialConfig(), FOLIAGE.voxel)
    )
    layout, field = load_field("trial")
    pr = plan(layout, field=field)
    xy = [field.cand_xy[field.candidate_index(c)] for c in pr.selected]
    print(f"plan: {len(xy)} scan locations on the nominal boxes")
    by_seed: list[ev.SeedScore] = []
    beside: list[ev.SeedScore] = []
    out: dict[str, Any] = {"seeds": args.seeds, "dates": [d.isoformat() for d in DATES]}
    with tempfile.TemporaryDirectory() as d:
        runs = Path(d) if args.keep is None else args.keep
        season_runs: list[Path] = []
        for seed in args.seeds:
            try:
                followed, nominal, mp = _season(seed, xy, pr, runs, args.step, out)
            except Exception as exc:
                bench.fail(f"seed {seed}", f"{type(exc).__name__}: {exc}")
                continue
            by_seed.append(followed)
            beside.append(nominal)
            print(ev.describe(followed))
            print("the second date on the nominal plan:", ev.describe(nominal), sep="\n")
            if not season_runs:
                season_runs = [runs / _run_name(seed, day) for day in DATES]
                _plan_experiment(bench, seed, DATES[-1], pr, mp, out)
        fig.record_scores(bench, by_seed)
        fig.record_beside(bench, beside)
        if not args.no_timings:
            _timings(bench, args, season_runs, xy, pr, runs, out)
    out["scores"] = [msgspec.to_builtins(s) for s in by_seed]
    return bench.finish(args.json, out)


def _run_name(seed: int, date: datetime.date, plan: str = "") -> str:
    return f"trial-s{seed}-{date.isoformat()}{plan}"


def _season(
    seed: int, xy: list[Any], pr: PlanResult, runs: Path, step: float, out: dict[str, Any]
) -> tuple[ev.SeedScore, ev.SeedScore, PlanResult]:
    """One seed's season as a user flies it: the first date on the plan on the nominal
    boxes, the second on the plan made from the first date's crop
    (``phenorover plan --from-survey``), scored with the growth the product's season
    step measures; and, like for like, the same second date flown on the nominal plan.
    Returns both scores and the plan from the survey."""
    from phenorover.eval.plan_survey import locations
    from services.planner.measured import plan_measured

    first = simulate(seed, DATES[0], xy, pr, runs, step)
    assert first[0].crop is not None
    layout, field = load_field("trial")
    mp = plan_measured(layout, field, first[0].crop)
    then = simulate(seed, DATES[1], list(locations(mp)), mp, runs, step)
    same = simulate(seed, DATES[1], xy, pr, runs, step, plan="-nominal")
    out.setdefault("locations_from_survey", []).append(len(mp.selected))
    scores = []
    for name, second in (("plan from the survey", then), ("nominal plan", same)):
        print(f"seed {seed}, {name}: registered in {first[2]:.1f} + {second[2]:.1f} s")
        # growth as the product's season step measures it (dates checked against each
        # other on stable ground, one ground for both)
        s = season([first[0].run_dir, second[0].run_dir], TraitsConfig())
        grew = np.nansum(s.growth, axis=0)
        grew[np.isnan(s.growth).any(axis=0)] = np.nan
        off = s.offsets[-1]
        mm = None if off is None else off.median_m * 1e3
        out.setdefault("offsets_mm", {}).setdefault(name, []).append(mm)
        dates = [first[:2], second[:2]]
        scores.append(ev.score_seed(seed, dates, heritability, grew))
    return scores[0], scores[1], mp


def _plan_experiment(
    bench: Bench,
    seed: int,
    then: datetime.date,
    pr: PlanResult,
    mp: PlanResult,
    out: dict[str, Any],
) -> None:
    """The plan on the crop a survey measured (``mp``) against the plan on the nominal
    boxes (``pr``): the true foliage cells each plan's scans see (0.5 deg) in the
    world of the next survey (on ``then``), with each plan's locations and tour
    beside them (the measured crop may need more of them)."""
    from phenorover.eval.plan_survey import compare_plans, locations

    try:
        layout, field = load_field("trial")
        world = World(layout, field, world_config(seed, then))
        cmp = compare_plans(world, locations(pr), locations(mp))
    except Exception as exc:
        bench.fail("plan from the survey", f"{type(exc).__name__}: {exc}")
        fig.record_plan(bench, None, None, None, str(exc))
        return
    cmp["tour_m"] = {"nominal": pr.tour.length, "measured": mp.tour.length}
    out["plan_from_survey"] = cmp
    print("plan from the survey:", cmp)
    fig.record_plan(bench, cmp, pr, mp)


def _timings(
    bench: Bench,
    args: argparse.Namespace,
    season_runs: list[Path],
    xy: list[Any],
    pr: PlanResult,
    runs: Path,
    out: dict[str, Any],
) -> None:
    """``phenorover traits`` on one survey and on five dates of one seed."""
    if not season_runs:
        fig.record_times(bench, None, None, "no survey was simulated")
        return
    try:
        one = _cli_time(season_runs[-1:])
        for date in SEASON:
            rt, _, _ = simulate(args.seeds[0], date, xy, pr, runs, args.step)
            season_runs.append(rt.run_dir)
        five = _cli_time(season_runs)
    except Exception as exc:
        bench.fail("timings", f"{type(exc).__name__}: {exc}")
        fig.record_times(bench, None, None, str(exc))
        return
    out["cli_s"] = {"one": one, "five": five}
    fig.record_times(bench, one, five)


if __name__ == "__main__":
    sys.exit(main())
