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
from collections.abc import Callable, Sequence
from typing import Any

import msgspec
import numpy as np
import numpy.typing as npt

from common.arrays import F64

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
