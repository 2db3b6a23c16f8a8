"""The heritability fits in a worker process give what fitting here gives, and a
worker that dies costs the fits' time, never the run's heritabilities."""

from __future__ import annotations

import numpy as np

from common.canopy import CanopyDefinition
from common.field_model import PlotRecord
from services.traits import breeding
from services.traits.compute import NAMES, OK, TraitTable
from services.traits.fits import Fits


def _trial(seed: int) -> TraitTable:
    """Ten entries in three reps, every trait an entry effect plus noise."""
    rng = np.random.default_rng(seed)
    records = [
        PlotRecord(plot=str(100 * r + e), row=r, column=e, entry=f"E{e}", rep=r)
        for r in range(1, 4)
        for e in range(10)
    ]
    effect = rng.normal(1.0, 0.2, (10, len(NAMES)))
    values = np.array([effect[int(rec.column)] for rec in records])
    values += rng.normal(0.0, 0.1, values.shape)
    return TraitTable(records, values, [OK] * len(records), "2026-07-01", CanopyDefinition())


def test_fits_in_the_worker_are_the_fits_made_here() -> None:
    tables = [_trial(1), _trial(2)]
    with Fits() as fits:
        for t in tables:
            fits.submit(t)
        got = [fits.next() for _ in tables]
    for t, h2 in zip(tables, got, strict=True):
        assert h2 == breeding.heritabilities(t)
        assert all(h.ok and 0.0 < h.h2_mean < 1.0 for h in h2.values())


def test_a_dead_worker_leaves_the_fits_to_this_process() -> None:
    table = _trial(3)
    with Fits() as fits:
        fits.submit(table)
        fits._worker.close(ok=False)  # killed with a job: its pipe closes
        fits.submit(table)
        assert fits.next() == breeding.heritabilities(table)
        assert fits.next() == breeding.heritabilities(table)
