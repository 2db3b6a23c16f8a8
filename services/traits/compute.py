"""Per-plot traits of one registered survey: the ground (:mod:`.ground`), every
point's height above it, the cloud cut by every plot footprint at once, and
:func:`common.canopy.plot_traits` on each plot's points (the one definition of the
traits, shared with the simulator's truth).

A plot's quality: ``ok``; ``occluded`` when the share of its length the survey saw
from both lanes (``seen``, :mod:`common.canopy`) is below ``min_seen``: a side not
seen leaves the canopy's far extent out of its cover and volume; ``no points`` when
the survey saw nothing of it (its traits are NaN).
:func:`compute_run` is the one entry point for a run folder, reused by the
multi-date (season) step.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path

import numpy as np
import numpy.typing as npt

from common.arrays import F64, I64
from common.canopy import TRAITS, CanopyDefinition, plot_traits
from common.cropmodel import CropModel, assign_plots, by_plot, crop_model
from common.field import Field, FieldLayout
from services.traits.config import TraitsConfig
from services.traits.ground import GroundError, GroundModel, fit_ground
from services.traits.hidden import occupied_voxels
from services.traits.run import Record, RunError, RunInput, load_run
from services.traits.season import Offset

log = logging.getLogger("phenorover.traits")

OK, OCCLUDED, NO_POINTS = "ok", "occluded", "no points"
NAMES: tuple[str, ...] = tuple(TRAITS)


@dataclasses.dataclass(frozen=True)
class TraitTable:
    """The traits of every plot: ``values`` (P, len(NAMES)) in :data:`NAMES` order
    (:data:`common.canopy.TRAITS`, NaN where undefined), ``quality`` per plot, the
    field book ``records`` in plot order, the survey ``date`` ("" unknown) and the
    ``definition`` they were computed with."""

    records: list[Record]
    values: F64
    quality: list[str]
    date: str
    definition: CanopyDefinition

    def column(self, trait: str) -> F64:
        """One trait for every plot (P,)."""
        return self.values[:, NAMES.index(trait)]


@dataclasses.dataclass(frozen=True)
class RunTraits:
    """One run's traits and what they came from (:func:`compute_run`). ``timings``:
    seconds per stage."""

    run_dir: Path
    mission: str
    layout: FieldLayout
    field: Field
    records: list[Record]
    table: TraitTable
    ground: GroundModel
    date: str
    date_source: str
    timings: dict[str, float]
    # the plots as measured, for planning the next survey (``crop.json``)
    crop: CropModel | None = None


def quality_of(traits: dict[str, float], min_seen: float) -> str:
    if traits["points"] == 0:
        return NO_POINTS
    return OCCLUDED if traits["seen"] < min_seen else OK


def trait_table(
    xy: F64,
    h: F64,
    field: Field,
    records: list[Record],
    cfg: TraitsConfig,
    date: str,
    groups: tuple[I64, I64],
    voxels: F64 | None = None,
) -> TraitTable:
    """The :class:`TraitTable` of points ``xy`` (N, 2) at heights ``h`` above the
    ground over ``field``'s plots; ``groups``: each plot's points
    (:func:`common.cropmodel.by_plot`); ``voxels``: each plot's occupied voxels as
    the survey's rays estimate them (:mod:`.hidden`; without: those holding a
    point)."""
    boxes = field.plot_boxes
    order, starts = groups
    values = np.full((len(boxes), len(NAMES)), np.nan)
    quality: list[str] = []
    for k in range(len(boxes)):
        idx = order[starts[k] : starts[k + 1]]
        foot = boxes[k, [0, 1, 3, 4]]
        count = None if voxels is None else float(voxels[k])
        t = plot_traits(xy[idx], h[idx], foot, cfg.definition, count)
        quality.append(quality_of(t, cfg.min_seen))
        values[k] = [t[n] for n in NAMES]
    return TraitTable(records, values, quality, date, cfg.definition)


Found = tuple[F64, GroundModel, float, npt.NDArray[np.bool_]]


def field_ground(inp: RunInput, cfg: TraitsConfig) -> Found:
    """The run's points over its field (and ``crop_margin`` around it), the ground
    found in them, the seconds it took and which of the run's points they are;
    raises RunError when no ground is found."""
    b = inp.field.bounds
    m = cfg.ground.crop_margin
    xyz = inp.cloud
    t = time.perf_counter()
    keep = (
        (xyz[:, 0] >= b[0] - m)
        & (xyz[:, 0] <= b[2] + m)
        & (xyz[:, 1] >= b[1] - m)
        & (xyz[:, 1] <= b[3] + m)
    )
    xyz = xyz[keep]
    try:
        ground = fit_ground(xyz, np.array([b[0] - m, b[1] - m, b[2] + m, b[3] + m]), cfg.ground)
    except GroundError as exc:
        raise RunError(f"{inp.run_dir / 'registered.laz'}: {exc}") from None
    took = time.perf_counter() - t
    log.info(
        "ground: %d of %d points in the field, %d x %d cells of %.2f m (%.1f s)",
        len(xyz), len(inp.cloud), *ground.shape[::-1], ground.cell, took,
    )  # fmt: skip
    return xyz, ground, took, keep


def compute_traits(
    inp: RunInput,
    cfg: TraitsConfig,
    found: Found | None = None,
    heights_from: GroundModel | None = None,
    offset: Offset | None = None,
) -> RunTraits:
    """The traits of a read run (:func:`.run.load_run`); raises RunError when no
    ground is found. ``found``: :func:`field_ground` of this run, when already
    computed. ``heights_from``: the ground heights are measured from (default: the
    run's own), raised by ``offset`` (a season's reference date's ground, moved onto
    this date by the offset between them, :meth:`.season.Offset.at`)."""
    xyz, ground, took, keep = found if found is not None else field_ground(inp, cfg)
    timings: dict[str, float] = {"ground": took}
    t = time.perf_counter()
    base = heights_from or ground
    h = xyz[:, 2] - base.height(xyz[:, 0], xyz[:, 1])
    if offset is not None:
        h -= offset.at(xyz[:, 0], xyz[:, 1])
    fld = inp.field
    plot = assign_plots(xyz[:, :2], fld.plot_boxes, fld.plot_row, fld.plot_col, 0.0)
    groups = by_plot(plot, fld.n_plots)
    voxels = None
    views = inp.scan_views()
    if views is not None:
        # the walk's layers stand on the ground the heights do (an offset of
        # millimetres moves none of them)
        voxels = occupied_voxels(
            xyz, h, groups, views, keep, fld, base, cfg.definition, cfg.min_seen
        )
        timings["hidden"] = time.perf_counter() - t
        log.info("occupied voxels, hidden ones counted: %.0f in %d plots (%.1f s)",
                 voxels.sum(), (voxels > 0).sum(), timings["hidden"])  # fmt: skip
    table = trait_table(xyz[:, :2], h, fld, inp.records, cfg, inp.date, groups, voxels)
    crop = crop_model(
        xyz[:, :2], h, inp.field, inp.layout, min_height=cfg.definition.min_height, date=inp.date
    )
    timings["traits"] = time.perf_counter() - t
    counts = {q: table.quality.count(q) for q in (OK, OCCLUDED, NO_POINTS)}
    log.info(
        "traits: %d plots (%s) (%.1f s)",
        len(table.quality),
        ", ".join(f"{n} {q}" for q, n in counts.items()),
        timings["traits"],
    )
    return RunTraits(
        run_dir=inp.run_dir,
        mission=str(inp.mission.get("id", "")),
        layout=inp.layout,
        field=inp.field,
        records=inp.records,
        table=table,
        ground=ground,
        date=inp.date,
        date_source=inp.date_source,
        timings=timings,
        crop=crop,
    )


def read_run(run_dir: str | Path, date: str | None = None) -> tuple[RunInput, float]:
    """:func:`.run.load_run`, logged, and the seconds it took; raises RunError."""
    t = time.perf_counter()
    inp = load_run(run_dir, date)
    read = time.perf_counter() - t
    log.info(
        "read %s: %d points, %d plots (%.1f s)", run_dir, len(inp.cloud), inp.field.n_plots, read
    )
    return inp, read


def compute_run(
    run_dir: str | Path, cfg: TraitsConfig | None = None, date: str | None = None
) -> RunTraits:
    """Read ``run_dir`` and compute its traits (``date``: ``--date``, see
    :mod:`.run`); raises RunError."""
    inp, read = read_run(run_dir, date)
    out = compute_traits(inp, cfg or TraitsConfig())
    out.timings["read"] = read
    return out
