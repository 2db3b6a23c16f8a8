"""Scoring measured per-plot traits against the simulator's plants: the same trait
definitions (:mod:`common.canopy`) applied to the true foliage (``services/sim/
plant_truth``), plot by plot. Pure: arrays in, figures out.

- heights (and growth between two dates): RMSE and bias (measured - true), metres;
- cover and volumes: the mean absolute relative error per plot and the relative bias
  of the field total, percent of the true value.

Plots the traits flag (too occluded to trust, no points) are left out and counted.
"""

from __future__ import annotations

import dataclasses
import math
import statistics
from collections.abc import Callable, Sequence
from typing import Any

import msgspec
import numpy as np
import numpy.typing as npt

from phenorover.eval.results import Bench, Goal, spread

F64 = npt.NDArray[np.float64]
B = npt.NDArray[np.bool_]
# heritability from (entries, reps, values): services.traits.stats.heritability
H2Fn = Callable[[list[str], list[int | None], F64], Any]


@dataclasses.dataclass(frozen=True)
class Error:
    """One trait's error over the scored plots: ``rmse`` and ``bias`` in the trait's
    unit, ``mape`` and ``rel_bias`` in percent of the truth (NaN where not meaningful),
    ``n`` plots scored, ``flagged`` plots left out."""

    rmse: float
    bias: float
    mape: float
    rel_bias: float
    n: int
    flagged: int


def error(measured: F64, true: F64, ok: B | None = None) -> Error:
    """Errors of ``measured`` against ``true`` (P,), over the plots ``ok`` keeps and
    where both are finite."""
    m, t = np.asarray(measured, dtype=np.float64), np.asarray(true, dtype=np.float64)
    keep = np.isfinite(m) & np.isfinite(t)
    if ok is not None:
        keep &= ok
    n = int(keep.sum())
    if n == 0:
        nan = float("nan")
        return Error(nan, nan, nan, nan, 0, int(len(m) - n))
    d = m[keep] - t[keep]
    pos = t[keep] > 0
    mape = float(np.mean(np.abs(d[pos]) / t[keep][pos]) * 100) if pos.any() else math.nan
    total = float(t[keep].sum())
    rel = float(d.sum() / total * 100) if total > 0 else math.nan
    return Error(
        rmse=float(np.sqrt(np.mean(d**2))),
        bias=float(d.mean()),
        mape=mape,
        rel_bias=rel,
        n=n,
        flagged=int(len(m) - n),
    )


TARGETS = {
    "height_rmse_cm": 2.0,
    "cover_mape_pct": 5.0,
    "volume_mape_pct": 5.0,
    "growth_rmse_cm": 2.0,
    "h2_abs_diff": 0.05,
    "one_s": 10.0,
    "season_s": 30.0,
}


class SeedScore(msgspec.Struct, frozen=True, kw_only=True):
    """One seed's scores: per date (in order) the errors of each scored trait, the
    growth in height between the first and last date, and heritability of height on
    the last date: measured (plots flagged ok), true on the same plots, true on all."""

    seed: int
    dates: list[str]
    errors: list[dict[str, Error]]
    growth: Error
    h2_measured: float
    h2_true: float
    h2_true_all: float
    h2_note: str


SCORED = ("height", "cover", "volume_voxel", "volume_hull")


def score_seed(
    seed: int,
    dates: Sequence[tuple[Any, list[dict[str, Any]]]],
    h2: H2Fn,
    growth: F64 | None = None,
) -> SeedScore:
    """Score one seed's surveys: ``dates`` of (measured traits with ``table``, the
    plants' truth rows); ``h2`` computes heritability from (entries, reps, values);
    ``growth``: the measured growth in height from the first to the last date (P,) as
    the season step gives it (default: the difference of the dates' own heights)."""
    errors, heights, true_heights = [], [], []
    for rt, truth in dates:
        ok = np.array([q == "ok" for q in rt.table.quality])
        errors.append({t: error(rt.table.column(t), _true(truth, t), ok) for t in SCORED})
        heights.append(np.where(ok, rt.table.column("height"), np.nan))
        true_heights.append(_true(truth, "height"))
    measured = heights[-1] - heights[0] if growth is None else growth
    grown = error(measured, true_heights[-1] - true_heights[0])
    recs = dates[-1][0].records
    entries, reps = [r.entry for r in recs], [r.rep for r in recs]
    # the true statistic on the same plots the measured one could use (the plots
    # flagged ok), and on every plot of the trial
    kept = np.where(np.isfinite(heights[-1]), true_heights[-1], np.nan)
    hm, ht = h2(entries, reps, heights[-1]), h2(entries, reps, kept)
    hall = h2(entries, reps, true_heights[-1])
    return SeedScore(
        seed=seed,
        dates=[rt.date for rt, _ in dates],
        errors=errors,
        growth=grown,
        h2_measured=hm.h2_mean if hm.ok else math.nan,
        h2_true=ht.h2_mean if ht.ok else math.nan,
        h2_true_all=hall.h2_mean if hall.ok else math.nan,
        h2_note=f"{hm.model}; measured: {hm.reason or 'ok'}; true: {ht.reason or 'ok'}",
    )


def _true(truth: list[dict[str, Any]], trait: str) -> F64:
    return np.array([math.nan if r.get(trait) is None else r[trait] for r in truth], dtype=float)


def describe(s: SeedScore) -> str:
    """A few lines for the console."""
    lines = []
    for date, errs in zip(s.dates, s.errors, strict=True):
        h, c, v = errs["height"], errs["cover"], errs["volume_voxel"]
        lines.append(
            f"seed {s.seed} {date}: height RMSE {h.rmse * 100:.2f} cm (bias "
            f"{h.bias * 100:+.2f} cm, {h.n} plots, {h.flagged} left out); cover "
            f"{c.mape:.1f} % (bias {c.rel_bias:+.1f} %); voxel volume {v.mape:.1f} % "
            f"(bias {v.rel_bias:+.1f} %); hull volume {errs['volume_hull'].mape:.1f} %"
        )
    lines.append(
        f"seed {s.seed}: growth RMSE {s.growth.rmse * 100:.2f} cm (bias "
        f"{s.growth.bias * 100:+.2f} cm); H2 of height {s.h2_measured:.3f} measured, "
        f"{s.h2_true:.3f} true on the same plots, {s.h2_true_all:.3f} on all"
    )
    return "\n".join(lines)


def error_models(step_deg: float, nav: dict[str, float], trial: Any) -> dict[str, str]:
    """The models the traits benchmark draws under: the survey's (navigation, FARO,
    terrain: as the registration benchmark) and the trial's growth and variation."""
    from phenorover.eval.error_models import faro, terrain
    from services.sim.world import WorldConfig

    w = WorldConfig()
    return {
        "navigation pose (drawn per scan)": (
            f"{100 * nav['xy_m']:g} cm horizontal, {100 * nav['z_m']:g} cm vertical, "
            f"{nav['yaw_deg']:g} deg heading (1 sigma, independent per scan)"
        ),
        **faro(w.scanner_noise, nav["tilt_deg"]),
        **terrain(w.terrain),
        "scan": f"{step_deg:g} deg steps from the planner's locations on the nominal boxes",
        "trial (services.sim.trial, assumptions)": (
            f"logistic growth, rate {trial.rate_per_day:g}/day, inflection "
            f"{trial.inflection_days:g} days; genetic sd height/width/density "
            f"{trial.entry_sd_height:g}/{trial.entry_sd_width:g}/{trial.entry_sd_density:g}, "
            f"plot sd {trial.plot_sd_height:g}/{trial.plot_sd_width:g}/"
            f"{trial.plot_sd_density:g} (log scale); gaps {trial.gap_rate:.0%} (runs "
            f"{trial.gap_run:g}); {trial.lean_share:.0%} of plants leaning "
            f"{trial.lean_deg_min:g}-{trial.lean_deg_max:g} deg"
        ),
    }


def _fig(bench: Bench, name: str, values: list[float], unit: str, **kw: Any) -> None:
    vals = [v for v in values if math.isfinite(v)]
    value = statistics.mean(vals) if vals else None
    note = spread(vals)
    bench.figure(name, value, unit, note=note, missing="no seed measured it", **kw)


def record_scores(bench: Bench, seeds: Sequence[SeedScore]) -> None:
    """The accuracy figures, each the mean over the seeds with their spread."""
    close = {
        "height": "a scanner position that sees the canopy top (a mast above the crop), "
        "or a smaller CHM percentile",
        "cover": "cells seen from above; more scan locations per plot",
        "volume": "more scan locations (the canopy's far side is occluded from one lane)",
        "h2": "a smaller height error (the plot noise it adds lowers H2)",
    }
    for k in range(len(DATE_LABELS)):
        label = DATE_LABELS[k]
        errs = [s.errors[k] for s in seeds if k < len(s.errors)]
        _fig(
            bench,
            f"canopy height RMSE against the truth ({label})",
            [e["height"].rmse * 100 for e in errs],
            "cm",
            goal=Goal("<=", TARGETS["height_rmse_cm"], close["height"]),
            headline=k == len(DATE_LABELS) - 1,
        )
        _fig(bench, f"canopy height bias ({label})", [e["height"].bias * 100 for e in errs], "cm")
        _fig(
            bench,
            f"projected cover, mean abs. error per plot ({label})",
            [e["cover"].mape for e in errs],
            "%",
            goal=Goal("<=", TARGETS["cover_mape_pct"], close["cover"]),
        )
        for t, name in (("volume_voxel", "voxel volume"), ("volume_hull", "hull volume")):
            _fig(
                bench,
                f"{name}, mean abs. error per plot ({label})",
                [e[t].mape for e in errs],
                "%",
                goal=Goal("<=", TARGETS["volume_mape_pct"], close["volume"])
                if t == "volume_voxel"
                else None,
            )
        _fig(
            bench,
            f"plots left out as occluded or empty ({label})",
            [float(e["height"].flagged) for e in errs],
            "plots",
        )
    _fig(
        bench,
        "growth in height between the dates, RMSE against the true growth",
        [s.growth.rmse * 100 for s in seeds],
        "cm",
        goal=Goal("<=", TARGETS["growth_rmse_cm"], close["height"]),
        headline=True,
    )
    _fig(
        bench,
        "heritability (entry-mean H2) of height: |measured - true|, same plots",
        [abs(s.h2_measured - s.h2_true) for s in seeds],
        "",
        goal=Goal("<=", TARGETS["h2_abs_diff"], close["h2"]),
        headline=True,
    )
    _fig(bench, "heritability of height, measured", [s.h2_measured for s in seeds], "")
    _fig(
        bench,
        "heritability of height, true plants, the same plots",
        [s.h2_true for s in seeds],
        "",
    )
    _fig(
        bench,
        "heritability of height, true plants, every plot (flagged ones too)",
        [s.h2_true_all for s in seeds],
        "",
    )


def record_times(bench: Bench, one: float | None, five: float | None, why: str = "") -> None:
    """``phenorover traits`` wall times (one seed's runs)."""
    bench.figure(
        "phenorover traits, one 60-plot survey (wall, the command)",
        one,
        "s",
        goal=Goal("<=", TARGETS["one_s"], "CSF on fewer points (a coarser lowest-point grid)"),
        headline=True,
        missing=why,
    )
    bench.figure(
        "phenorover traits, a season of five dates (wall, the command)",
        five,
        "s",
        goal=Goal("<=", TARGETS["season_s"], "the dates read and computed in parallel"),
        headline=True,
        missing=why,
    )


def record_plan(
    bench: Bench, cmp: dict[str, Any] | None, nominal: Any, measured: Any, why: str = ""
) -> None:
    """Planning from the survey against planning on the nominal boxes: the true foliage
    cells each plan's scans see, with their locations and tour lengths beside."""
    base = None if cmp is None else 100 * cmp["nominal"]["share"]
    for name, plan in (("nominal", nominal), ("measured", measured)):
        c = None if cmp is None else cmp[name]
        note = ""
        if cmp is not None and c is not None:
            note = (
                f"{c['cells_seen']} of {cmp['cells_total']} true cells from "
                f"{c['locations']} locations, tour {plan.tour.length:.1f} m"
            )
        goal = None
        if name == "measured" and base is not None:
            goal = Goal(">=", base, "more scan locations where the measured crop is hidden")
        bench.figure(
            f"true foliage cells seen, plan on the {name} boxes",
            None if c is None else 100 * c["share"],
            "%",
            note=note,
            missing=why or "not measured",
            goal=goal,
            headline=name == "measured",
        )


DATE_LABELS = ("70 days after planting", "91 days after planting")
