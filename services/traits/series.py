"""A season: the traits of several surveys of one field, as per-plot series.

Before any change is measured the dates are checked against each other on stable
ground (lanes and headlands, more than ``stable_margin`` from every plot): the median
vertical offset of each date's ground against the earliest date's
(:func:`.season.vertical_offset`), with the tilt between the two registrations (a
plane fitted to the same cells). Heights are then measured above one ground for
every date, the earliest survey's (it sees the most bare soil; under a closed canopy
a later survey's ground is interpolated from the lanes), moved onto each date by that
plane when it exceeds ``offset_tolerance_m`` anywhere over the stable ground
(smaller ones are within what registration achieves, and correcting them would add
their noise). Then per plot:
growth between consecutive dates, and a logistic growth curve (:func:`.season.
fit_logistic`) once there are three dates or more.

Refused, one line each: runs of different fields, runs without a date, two runs of
one date.
"""

from __future__ import annotations

import dataclasses
import datetime
import functools
import itertools
import logging
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from common.arrays import F64
from common.cluster import file_stamp
from services.traits.compute import OK, Found, RunTraits, compute_traits, field_ground
from services.traits.config import TraitsConfig
from services.traits.ground import GroundModel
from services.traits.run import RunError, RunInput, load_run
from services.traits.season import LogisticFit, Offset, fit_all, growth, vertical_offset

log = logging.getLogger("phenorover.traits")


@dataclasses.dataclass(frozen=True)
class Season:
    """Several dates of one field, in date order. ``days``: days after planting (the
    field's ``planting_date``; without one, days since the first survey);
    ``offsets[d]``: date ``d``'s ground against the first date's (None for the first);
    ``corrected[d]``: whether heights were moved by it; ``height`` (D, P): the height
    trait of the plots flagged ok (NaN otherwise); ``growth`` (D - 1, P); ``fits``
    per plot (empty with fewer than three dates)."""

    runs: list[RunTraits]
    days: F64
    offsets: list[Offset | None]
    corrected: list[bool]
    height: F64
    growth: F64
    fits: list[LogisticFit]


def _same_field(inputs: Sequence[RunInput]) -> None:
    a = inputs[0]
    for b in inputs[1:]:
        same = a.layout.name == b.layout.name and np.array_equal(
            a.field.plot_boxes, b.field.plot_boxes
        )
        if not same:
            raise RunError(
                f"{a.run_dir} and {b.run_dir} are surveys of different fields "
                f"({a.layout.name!r}, {a.field.n_plots} plots; {b.layout.name!r}, "
                f"{b.field.n_plots} plots)"
            )


def _dated(inputs: Sequence[RunInput]) -> list[RunInput]:
    for inp in inputs:
        if not inp.date:
            raise RunError(
                f"{inp.run_dir}: no survey date, which a season needs (a mission on a "
                "wall clock has one; a simulated one takes [services.sim.world.trial] date)"
            )
    ordered = sorted(inputs, key=lambda i: i.date)
    for a, b in itertools.pairwise(ordered):
        if a.date == b.date:
            raise RunError(f"{a.run_dir} and {b.run_dir} are both surveys of {a.date}")
    return ordered


def _days(inputs: Sequence[RunInput]) -> F64:
    dates = [datetime.date.fromisoformat(i.date) for i in inputs]
    start = inputs[0].layout.planting_date or dates[0]
    return np.array([(d - start).days for d in dates], dtype=np.float64)


def season(run_dirs: Sequence[str | Path], cfg: TraitsConfig, by: Map | None = None) -> Season:
    """Read and compute the traits of every run as one season; raises RunError.
    ``by``: where each run is read and computed (:meth:`common.cluster.Cluster.map`,
    a Dask cluster, when the run folders are on a file system its workers share;
    default: here), in three passes: each run read and checked against the others,
    its ground, then its traits on the season's ground. The same season either way."""
    by = by or _here
    try:
        # the runs checked against each other before any ground is looked for
        inputs = _dated(by(_input, [_run(r) for r in run_dirs]))
        _same_field(inputs)
        grounds = by(_ground, [(*_run(inp.run_dir), cfg) for inp in inputs])
        offsets, corrected = _offsets(inputs, grounds, cfg)
        ref = grounds[0]
        jobs: list[tuple[Any, ...]] = [(*_run(inputs[0].run_dir), cfg, None, None)]
        for inp, off in zip(inputs[1:], offsets[1:], strict=True):
            assert off is not None
            jobs.append((*_run(inp.run_dir), cfg, ref, off if off.exceeds else None))
        runs = by(_traits, jobs)
    finally:
        forget()
    days = _days(inputs)
    ok = np.array([[q == OK for q in r.table.quality] for r in runs])
    height = np.where(ok, np.array([r.table.column("height") for r in runs]), np.nan)
    fits = fit_all(days, height) if len(runs) >= 3 else []
    return Season(runs, days, offsets, corrected, height, growth(height, days), fits)


def _offsets(
    inputs: list[RunInput], grounds: list[GroundModel], cfg: TraitsConfig
) -> tuple[list[Offset | None], list[bool]]:
    """Each date's ground against the first's on stable ground (None for the first),
    and whether it exceeds the tolerance."""
    ref = grounds[0]
    boxes = inputs[0].field.plot_boxes
    stable_ref = ref.stable_mask(boxes, cfg.stable_margin)
    gx, gy = ref.centres()
    cx, cy = np.meshgrid(gx, gy)  # (ny, nx), as the ground grids
    offsets: list[Offset | None] = [None]
    corrected = [False]
    for inp, g in zip(inputs[1:], grounds[1:], strict=True):
        try:
            off = vertical_offset(
                ref.z,
                g.z,
                stable_ref & g.stable_mask(boxes, cfg.stable_margin),
                tolerance_m=cfg.offset_tolerance_m,
                centres=(cx, cy),
            )
        except ValueError as exc:
            raise RunError(f"{inp.run_dir} against {inputs[0].run_dir}: {exc}") from None
        offsets.append(off)
        corrected.append(off.exceeds)
        plane = off.plane or (off.median_m, 0.0, 0.0)
        log.info(
            "%s: ground %+.1f mm against %s over %d stable cells (tilt %+.2f, %+.2f "
            "mm/m)%s",
            inp.date, off.median_m * 1000, inputs[0].date, off.n_cells,
            plane[1] * 1000, plane[2] * 1000, ", corrected" if off.exceeds else "",
        )  # fmt: skip
    return offsets, corrected


# runs fn(*job) for every job, the results in the jobs' order
Map = Callable[[Callable[..., Any], Sequence[tuple[Any, ...]]], list[Any]]


def _here(fn: Callable[..., Any], jobs: Sequence[tuple[Any, ...]]) -> list[Any]:
    return [fn(*job) for job in jobs]


# a run as a season's tasks name it: its folder, and the stamp of the files read from
# it, so that a long-running worker's cache never serves a run as it was before
Stamp = tuple[tuple[str, int, int], ...]


def _run(run_dir: str | Path) -> tuple[str, Stamp]:
    d = Path(run_dir)
    return str(d), file_stamp(d / "registered.laz", d / "registered.e57", d / "mission.db")


def _input(run_dir: str, stamp: Stamp) -> RunInput:
    """A run's input without its cloud: what the season checks."""
    return dataclasses.replace(_read(run_dir, stamp), cloud=np.zeros((0, 3)), source=None)


def _ground(run_dir: str, stamp: Stamp, cfg: TraitsConfig) -> GroundModel:
    return _found(run_dir, stamp, cfg)[1]


def _traits(
    run_dir: str, stamp: Stamp, cfg: TraitsConfig, ref: GroundModel | None, offset: Offset | None
) -> RunTraits:
    """A run's traits, heights above ``ref`` moved by ``offset`` (None: its own)."""
    inp, found = _read(run_dir, stamp), _found(run_dir, stamp, cfg)
    return compute_traits(inp, cfg, found, heights_from=ref, offset=offset)


# once per process for a season's passes (a Dask worker may get another run's next)
@functools.lru_cache(maxsize=16)
def _read(run_dir: str, stamp: Stamp) -> RunInput:
    return load_run(run_dir)


@functools.lru_cache(maxsize=16)
def _found(run_dir: str, stamp: Stamp, cfg: TraitsConfig) -> Found:
    return field_ground(_read(run_dir, stamp), cfg)


def forget() -> None:
    """Drop the runs this process read for a season (a worker's, when it is done)."""
    _read.cache_clear()
    _found.cache_clear()
