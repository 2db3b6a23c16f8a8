"""How the simulator's plants are made: the canopy generator (:mod:`services.sim.foliage`)
and the breeding trial grown to a date (:mod:`services.sim.trial`). Their options, in
the manifest's ``[services.sim.world.foliage]`` and ``[services.sim.world.trial]``."""

from __future__ import annotations

import datetime
from typing import Annotated

import msgspec

Sd = Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]
Share = Annotated[float, msgspec.Meta(ge=0.0, lt=1.0)]
Deg = Annotated[float, msgspec.Meta(ge=0.0, le=60.0)]


class FoliageConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Canopy generator (metres). The paper thinned ENGR plots to "less than 20
    plants" per 3 m plot (so ~6 plants/m) and modelled mature cotton as filling its
    1.9 m box; the remaining shape parameters are assumptions that give a canopy that
    is porous near its edge and nearly opaque over ~0.5 m of depth, as mature cotton is.
    """

    voxel: Annotated[float, msgspec.Meta(gt=0.005, le=0.5)] = 0.04
    """The plants' voxel size (m); their true heights are the voxels' top faces."""
    plants_per_m: Annotated[float, msgspec.Meta(gt=0, le=100)] = 6.0
    """Plants per metre of row (the paper's thinned ENGR plots)."""
    height_min: Annotated[float, msgspec.Meta(gt=0, le=1)] = 0.85
    """The lowest plant height, as a share of the plot box's height (an unvaried plot's
    plants are drawn uniformly between this and ``height_max``)."""
    height_max: Annotated[float, msgspec.Meta(gt=0, le=1)] = 1.0
    """The highest plant height, as a share of the plot box's height."""
    branches_per_plant: Annotated[int, msgspec.Meta(ge=0, le=200)] = 14
    """Branches rising outwards from each main stem."""
    leaves_per_branch: Annotated[int, msgspec.Meta(ge=0, le=100)] = 8
    """Leaf clusters along each branch."""
    leaf_radius: Annotated[float, msgspec.Meta(gt=0, le=1)] = 0.08
    """A leaf cluster's radius (m)."""
    leaf_fill: Annotated[float, msgspec.Meta(gt=0, le=1)] = 0.4
    """The share of each leaf cluster's volume that is filled: under 1 keeps clusters
    porous."""
    stem_radius: Annotated[float, msgspec.Meta(ge=0, le=0.2)] = 0.006
    """The stems' radius (m)."""


class TrialConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """How the trial varies and when it is surveyed (days, metres, degrees; sd are on
    the log scale, so about relative for these sizes, and a factor is never <= 0).
    Growth: ``size(t) = 1 / (1 + exp(-rate_per_day * (t - inflection_days)))`` of the
    mature size at t days after planting; height grows with ``size``, the canopy's
    half-width with ``size ** width_exponent``. Assumption: cotton has most of its
    height by 90-110 days after planting (size 0.94 at 90, 0.99 at 110 with these
    defaults). Gaps come in runs: a failure is followed by another with probability
    ``gap_run`` (mean run 1 / (1 - gap_run) positions); the paper's ENGR plots were
    sown with 40 seeds and thinned to under 20 plants, which leaves few but real holes.
    """

    date: datetime.date | None = None
    """The survey date; none: mature plants. A date needs the layout's
    ``planting_date`` and may not be before it."""
    vary: bool = False
    """Vary the plots even without a field book (every plot its own entry)."""
    rate_per_day: Annotated[float, msgspec.Meta(gt=0.0, le=1.0)] = 0.08
    """The logistic growth curve's rate (1/day)."""
    inflection_days: Annotated[float, msgspec.Meta(ge=0.0, le=365.0)] = 55.0
    """The growth curve's inflection, in days after planting."""
    width_exponent: Annotated[float, msgspec.Meta(ge=0.0, le=2.0)] = 0.5
    """The canopy's half-width grows with ``size ** width_exponent``: young plants are
    broader than tall for their final shape."""
    height_mean: Annotated[float, msgspec.Meta(gt=0.0, le=1.0)] = 0.85
    """Mean mature plant height as a share of the plot box's height (assumption; the
    box is the paper's mature-canopy envelope, never exceeded: heights are clipped to
    it), so genotypes mostly span about 0.65-1.0 of the box."""
    plant_spread: Share = 0.08
    """Plant-to-plant height spread in a plot, uniform +- this share (assumption: as
    the uniform 0.85-1.0 draw of an unvaried plot)."""
    entry_sd_height: Sd = 0.08
    """The genetic (per entry) sd of the height factor (assumption: entries differ
    about twice as much as reps of one entry, a heritable trait in a good trial)."""
    entry_sd_width: Sd = 0.08
    """The genetic sd of the canopy width factor."""
    entry_sd_density: Sd = 0.15
    """The genetic sd of the planting density factor."""
    plot_sd_height: Sd = 0.04
    """The environmental (per plot) sd of the height factor."""
    plot_sd_width: Sd = 0.04
    """The environmental sd of the canopy width factor."""
    plot_sd_density: Sd = 0.08
    """The environmental sd of the planting density factor."""
    gap_rate: Share = 0.06
    """The overall probability that a planted position fails to emerge."""
    gap_run: Share = 0.5
    """The probability that a failed position is followed by another."""
    lean_share: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 0.08
    """The share of plants leaning across the row, towards either lane (assumption: a
    few lodged plants per plot)."""
    lean_deg_min: Deg = 15.0
    """The least lean from vertical (deg)."""
    lean_deg_max: Deg = 30.0
    """The most lean from vertical (deg)."""
    lean_margin: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 0.15
    """How far a leaning canopy may leave the plot box sideways (m; the stem's lean is
    capped so its tip stays inside that)."""
