"""A regular field's visibility by translation of one candidate's table equals the
table cast candidate by candidate, pair for pair; a field that is not a lattice, or
too small to hold a whole range inside it, is cast candidate by candidate."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from common.field import ScannerModel, build_field, load_field
from phenorover.eval.fields import engr_sized
from services.planner.lattice import lattice_of
from services.planner.visibility import compute_visibility

# a short range, so that a small field holds a whole range inside it
SHORT = ScannerModel(max_range=10.0)


@pytest.mark.parametrize("mode", ["exact", "grid"])
def test_translated_table_is_the_cast_table(mode: str) -> None:
    field = build_field(engr_sized(20, 10))
    lat = lattice_of(field, SHORT.max_range)
    assert lat is not None
    moved = compute_visibility(field, SHORT, mode, step_deg=1.0)
    cast = compute_visibility(field, SHORT, mode, step_deg=1.0, translate=False)
    assert len(cast.cand) > 50_000
    for name in ("cand", "cell", "hits", "range_min"):
        assert np.array_equal(getattr(moved, name), getattr(cast, name)), name
    # one candidate cast, not every one
    assert moved.rays < cast.rays / 10


def test_a_field_that_is_no_lattice_or_too_small_is_cast() -> None:
    field = build_field(engr_sized(20, 10))
    assert lattice_of(field, 70.0) is None  # no candidate has its range inside the field
    assert lattice_of(load_field("engr")[1], 70.0) is None
    # one plot a centimetre off its place
    boxes = field.plot_boxes.copy()
    boxes[37, [0, 3]] += 0.01
    moved = dataclasses.replace(field, plot_boxes=boxes)
    assert lattice_of(moved, SHORT.max_range) is None
    # a candidate missing (a lane intersection failing clearance) leaves a lattice
    fewer = dataclasses.replace(
        field,
        cand_xy=field.cand_xy[1:],
        cand_ids=field.cand_ids[1:],
        cand_row_lane=field.cand_row_lane[1:],
        cand_cross_lane=field.cand_cross_lane[1:],
    )
    assert lattice_of(fewer, SHORT.max_range) is not None
    a = compute_visibility(fewer, SHORT)
    b = compute_visibility(fewer, SHORT, translate=False)
    assert np.array_equal(a.cell, b.cell) and np.array_equal(a.cand, b.cand)
