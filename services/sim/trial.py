"""A breeding trial grown to a survey date: what every plot's plants are built from.

A field whose layout has a field book with entries (or a world with ``vary = true``)
is a trial: every entry (genotype) has its own multiplicative genetic effects on the
plants' mature height, canopy width and planting density, every plot adds its own
environmental noise, some planted positions fail to emerge (in runs, so rows get holes)
and a few plants lean across the row into a lane. With a survey ``date`` the plants
are grown to it along a logistic curve in days after the layout's ``planting_date``;
without one they are at their full (mature) size. A field with no entries and no date
is no trial (:func:`plan_trial` returns None): its plots grow the foliage
generator's uniform plants, as the calibrated ENGR and SPL worlds do.

Randomness is keyed so nothing depends on what else is in the field: an entry's
effects come from (world seed, entry name), a plot's noise, gaps, leans and plant
heights from (world seed, plot index), each aspect from its own stream (changing the
gap rate does not change any height). Defaults are for cotton; where no source is
named they are assumptions.
"""

from __future__ import annotations

import dataclasses
import datetime
import math
import zlib

import numpy as np
import numpy.typing as npt

from common import fieldbook
from common.arrays import F64
from common.field import Field, FieldLayout
from common.field_model import PlotRecord
from services.sim.foliage import PlotGrowth
from services.sim.plant_config import FoliageConfig, TrialConfig

_ENTRY_TAG, _PLOT_TAG = 0x7A1A, 0x7A1B  # keep the trial's streams apart from the others'
_NOISE, _GAPS, _LEANS, _PLANTS = range(4)


@dataclasses.dataclass(frozen=True, eq=False)
class PlotPlan:
    """What plot ``plot`` (index, plot order) was grown from. ``effects``: its entry's
    genetic factors (height, width, density), ``noise`` the plot's own; heights in
    metres above the ground (``height_m_mature`` the plot's mean mature plant height,
    ``height_m`` the same at the survey date); ``width`` the canopy half-width factor at
    the date (x the plot's half width); ``density`` the planting density factor."""

    plot: int
    plot_id: str
    row: int
    column: int
    entry: str
    rep: int | None
    effects: tuple[float, float, float]
    noise: tuple[float, float, float]
    height_m_mature: float
    height_m: float
    width: float
    density: float
    growth: PlotGrowth

    @property
    def gaps(self) -> float:
        """Share of the planted positions that did not emerge."""
        return float(1.0 - self.growth.emerged.mean())

    @property
    def leaning(self) -> int:
        """Emerged plants that lean."""
        return int(np.count_nonzero(self.growth.lean_deg[self.growth.emerged]))

    @property
    def plants(self) -> int:
        return int(np.count_nonzero(self.growth.emerged))


@dataclasses.dataclass(frozen=True, eq=False)
class TrialPlan:
    """The whole trial: ``days`` after planting (None = mature) and ``size`` the growth
    factor then; ``varied``: entries, noise, gaps and leans apply."""

    config: TrialConfig
    planting_date: datetime.date | None
    days: int | None
    size: float
    varied: bool
    plots: tuple[PlotPlan, ...]


def growth(days: float, cfg: TrialConfig | None = None) -> float:
    """The share of the mature size reached ``days`` after planting (logistic; the
    default config's curve unless ``cfg``)."""
    cfg = cfg or TrialConfig()
    return 1.0 / (1.0 + math.exp(-cfg.rate_per_day * (days - cfg.inflection_days)))


def days_after_planting(cfg: TrialConfig, planting: datetime.date | None) -> int | None:
    """Days from ``planting`` to the survey date (None: no date, mature plants);
    ValueError (one line) without a planting date or with a date before it."""
    if cfg.date is None:
        return None
    if planting is None:
        raise ValueError(
            f"trial.date {cfg.date} needs the field's planting_date (the layout has none)"
        )
    days = (cfg.date - planting).days
    if days < 0:
        raise ValueError(f"trial.date {cfg.date} is before the field's planting_date {planting}")
    return days


def entry_effects(seed: int, entry: str) -> F64:
    """An entry's standard-normal genetic effects (height, width, density), from the
    world seed and the entry's name only (scaled by the sd in :func:`plan_trial`)."""
    ss = np.random.SeedSequence([seed, _ENTRY_TAG, zlib.crc32(entry.encode())])
    return np.random.default_rng(ss).standard_normal(3)


def emergence(n: int, rate: float, run: float, rng: np.random.Generator) -> npt.NDArray[np.bool_]:
    """Which of ``n`` positions along a row emerged: a two-state Markov chain whose
    failures have stationary share ``rate`` and repeat with probability ``run``."""
    # P(fail | neighbour emerged) that gives the stationary share `rate`
    start = min(1.0, rate * (1.0 - run) / (1.0 - rate))
    u = rng.uniform(size=n)
    failed = np.zeros(n, dtype=bool)
    prev = u[0] < rate
    failed[0] = prev
    for k in range(1, n):
        prev = bool(u[k] < (run if prev else start))
        failed[k] = prev
    return ~failed


def _plot_rng(seed: int, p: int, aspect: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([seed, _PLOT_TAG, p, aspect]))


def plan_trial(
    layout: FieldLayout, field: Field, foliage: FoliageConfig, cfg: TrialConfig, seed: int
) -> TrialPlan | None:
    """Every plot's plan, or None for a field that is no trial (no entries in its book,
    ``vary`` off and no date: the foliage generator's uniform plants). A dated field
    without entries grows the unvaried plants (``foliage``'s height range, no
    effects, gaps or leans) to the date. ValueError
    (one line) on a bad date; FieldError when the book does not match the field."""
    days = days_after_planting(cfg, layout.planting_date)
    recs = fieldbook.records(layout, field)
    varied = cfg.vary or any(r.entry for r in recs)
    if not varied and days is None:
        return None
    size = 1.0 if days is None else growth(days, cfg)
    sd_e = np.array([cfg.entry_sd_height, cfg.entry_sd_width, cfg.entry_sd_density])
    sd_p = np.array([cfg.plot_sd_height, cfg.plot_sd_width, cfg.plot_sd_density])
    plots = []
    for p, (rec, box) in enumerate(zip(recs, field.plot_boxes, strict=True)):
        # a plot without an entry is a genotype of its own
        entry = rec.entry or (f"plot {rec.plot}" if varied else "")
        if varied:
            eff = np.exp(sd_e * entry_effects(seed, entry))
            noise = np.exp(sd_p * _plot_rng(seed, p, _NOISE).standard_normal(3))
        else:
            eff = noise = np.ones(3)
        plots.append(_plot(p, rec, entry, box, eff, noise, size, foliage, cfg, seed, varied))
    return TrialPlan(
        config=cfg,
        planting_date=layout.planting_date,
        days=days,
        size=size,
        varied=varied,
        plots=tuple(plots),
    )


def _plot(
    p: int,
    rec: PlotRecord,
    entry: str,
    box: F64,
    eff: F64,
    noise: F64,
    size: float,
    foliage: FoliageConfig,
    cfg: TrialConfig,
    seed: int,
    varied: bool,
) -> PlotPlan:
    """One plot's plan (see :func:`plan_trial`)."""
    hz = float(box[5] - box[2])
    length = float(max(box[3] - box[0], box[4] - box[1]))  # the planted row
    density = float(eff[2] * noise[2])
    n = max(1, round(length * foliage.plants_per_m * density))
    rng = _plot_rng(seed, p, _PLANTS)
    if varied:
        frac = min(1.0, cfg.height_mean * float(eff[0] * noise[0]))
        spread = rng.uniform(1.0 - cfg.plant_spread, 1.0 + cfg.plant_spread, n)
        mature = np.minimum(frac * spread, 1.0) * hz
        emerged = emergence(n, cfg.gap_rate, cfg.gap_run, _plot_rng(seed, p, _GAPS))
        lr = _plot_rng(seed, p, _LEANS)
        leans = lr.uniform(size=n) < cfg.lean_share
        deg = lr.uniform(cfg.lean_deg_min, max(cfg.lean_deg_min, cfg.lean_deg_max), n)
        lean_deg = np.where(leans, deg * lr.choice([-1.0, 1.0], n), 0.0)
    else:  # a date but no trial: the unvaried plants, grown
        frac = (foliage.height_min + foliage.height_max) / 2
        mature = hz * rng.uniform(foliage.height_min, foliage.height_max, n)
        emerged, lean_deg = np.ones(n, dtype=bool), np.zeros(n)
    width = float(eff[1] * noise[1]) * size**cfg.width_exponent
    # a stem leans no farther than its tip can stay inside the box + margin
    half_w = float(min(box[3] - box[0], box[4] - box[1])) / 2
    h = np.maximum(mature * size, 1e-6)
    cap = np.degrees(np.arcsin(np.minimum(1.0, (half_w + cfg.lean_margin) / h)))
    lean_deg = np.sign(lean_deg) * np.minimum(np.abs(lean_deg), cap)
    lean_on = lean_deg[emerged] != 0
    return PlotPlan(
        plot=p,
        plot_id=rec.plot,
        row=rec.row,
        column=rec.column,
        entry=entry,
        rep=rec.rep,
        effects=(float(eff[0]), float(eff[1]), float(eff[2])),
        noise=(float(noise[0]), float(noise[1]), float(noise[2])),
        height_m_mature=frac * hz,
        height_m=frac * hz * size,
        width=width,
        density=density,
        growth=PlotGrowth(
            heights=mature * size,
            emerged=emerged,
            lean_deg=lean_deg,
            width=width,
            margin=cfg.lean_margin if lean_on.any() else 0.0,
        ),
    )
