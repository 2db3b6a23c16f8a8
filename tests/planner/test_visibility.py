"""Visibility: occlusion, hand-checked small cases, culling that changes nothing, and the
angular grid converging toward the exact (resolution-free) table."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from common.field import Field, FieldLayout, ScannerModel, build_field, load_field
from services.planner.visibility import Visibility, compute_visibility


def _with_candidates(field: Field, xy: list[tuple[float, float]]) -> Field:
    pts = np.array(xy, dtype=np.float64)
    n = len(pts)
    return dataclasses.replace(
        field,
        cand_xy=pts,
        cand_ids=np.arange(1, n + 1),
        cand_row_lane=np.zeros(n, dtype=np.int64),
        cand_cross_lane=np.zeros(n, dtype=np.int64),
    )


def _seen(vis: Visibility, cand: int = 0) -> set[int]:
    return set(vis.cell[vis.cand == cand].tolist())


@pytest.fixture(scope="module")
def one_row() -> Field:
    # one row of three 1 x 1 x 2 m plots, 1 m alleys, all taller than the scanner
    layout = FieldLayout(
        rows=1,
        plots_per_row=3,
        plot_length=1,
        plot_width=1,
        plot_height=2,
        row_spacing=1,
        alley_width=1,
        headland_width=2,
    )
    return build_field(layout)


def _face_cells(field: Field, plot: int, axis: int, end: int) -> set[int]:
    dims = field.cell_dims[plot]
    idx = np.arange(field.cell_offset[plot], field.cell_offset[plot + 1])
    loc = np.stack(np.unravel_index(idx - field.cell_offset[plot], tuple(dims)), axis=1)
    return set(idx[loc[:, axis] == (0 if end == 0 else dims[axis] - 1)].tolist())


@pytest.mark.parametrize("mode", ["exact", "grid"])
def test_plots_behind_a_plot_are_hidden(one_row: Field, mode: str):
    # the scanner on the row's axis, left of the row: only plot 0's -x face is in view
    y = float(one_row.plot_boxes[0, [1, 4]].mean())
    field = _with_candidates(one_row, [(one_row.plot_boxes[0, 0] - 1.5, y)])
    vis = compute_visibility(field, ScannerModel(), mode)
    front = _face_cells(one_row, 0, 0, 0)
    assert len(front) == 2 * 6  # 2 across x 6 layers
    if mode == "exact":
        assert _seen(vis) == front
    else:
        assert _seen(vis) <= front and len(_seen(vis)) >= 10


def test_single_plot_seen_from_a_corner_shows_two_sides(one_row: Field):
    b = one_row.plot_boxes[1]
    field = _with_candidates(one_row, [(b[0] - 0.5, b[1] - 0.5)])  # in front of -x and -y
    vis = compute_visibility(field, ScannerModel(min_range=0.1))
    seen_plot1 = {c for c in _seen(vis) if one_row.cell_plot[c] == 1}
    assert seen_plot1 == _face_cells(one_row, 1, 0, 0) | _face_cells(one_row, 1, 1, 0)


def test_range_and_field_of_view_limits(one_row: Field):
    y = float(one_row.plot_boxes[0, [1, 4]].mean())
    field = _with_candidates(one_row, [(one_row.plot_boxes[0, 0] - 1.5, y)])
    assert len(compute_visibility(field, ScannerModel(max_range=1.0)).cell) == 0
    # elevations 10..90 deg only: just cells reaching above 1 m + 1.5 m * tan(10 deg)
    up = compute_visibility(field, ScannerModel(vertical_start_deg=10.0))
    zs = one_row.cell_boxes[sorted(_seen(up)), 5]
    assert len(zs) > 0 and (zs > 1.0 + 1.5 * np.tan(np.radians(10))).all()


@pytest.mark.parametrize("name", ["engr", "spl"])
def test_side_culling_changes_nothing(name: str):
    _, field = load_field(name)
    a = compute_visibility(field, ScannerModel(), cull_sides=False)
    b = compute_visibility(field, ScannerModel())
    ka, kb = np.lexsort((a.cell, a.cand)), np.lexsort((b.cell, b.cand))
    assert np.array_equal(a.cand[ka], b.cand[kb]) and np.array_equal(a.cell[ka], b.cell[kb])
    assert np.array_equal(a.hits[ka], b.hits[kb])
    assert np.allclose(a.range_min[ka], b.range_min[kb])
    assert b.rays < a.rays / 10


def test_grid_converges_toward_exact():
    _, field = load_field("spl")
    exact = compute_visibility(field, ScannerModel()).matrix()
    recall = []
    for step in (1.44, 0.72, 0.36):
        grid = compute_visibility(field, ScannerModel(), "grid", step_deg=step).matrix()
        recall.append(grid.multiply(exact).nnz / exact.nnz)
        # rays only hit what a line of sight reaches (up to cell-edge slivers)
        assert (grid > exact).nnz <= 0.01 * grid.nnz
    assert recall[0] < recall[1] < recall[2]
    assert recall[2] > 0.7


def test_visibility_table_helpers():
    _, field = load_field("spl")
    vis = compute_visibility(field, ScannerModel())
    assert vis.matrix().shape == (77, field.n_cells)
    views = vis.cell_views()
    assert (views > 0).all()  # every cell seen from somewhere
    near = vis.cell_min_range()
    assert np.isfinite(near).all() and (near >= 0.6).all()
    assert vis.matrix(min_hits=1000).nnz == 0


def test_bad_mode_is_rejected():
    _, field = load_field("spl")
    with pytest.raises(ValueError, match="visibility mode 'fast'"):
        compute_visibility(field, ScannerModel(), "fast")
