"""Position tolerance of a plan, on the tiny field (ENGR's plot and lane sizes)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from common.field import Field, FieldLayout, ScannerModel, load_field
from common.messages.plan import PlanOptions
from phenorover.eval.tolerance import DIRECTIONS, RADII, STEP, free_run, tolerance
from services.planner.core import plan

TINY = Path(__file__).parents[1] / "data" / "tiny.toml"
OPTS = PlanOptions(cover="greedy")  # no CP-SAT (8 workers) in a unit test


@pytest.fixture(scope="module")
def tiny() -> tuple[FieldLayout, Field, np.ndarray]:
    layout, field = load_field(TINY)
    res = plan(layout, ScannerModel(), OPTS, field=field)
    xy = field.cand_xy[[field.candidate_index(i) for i in res.selected]]
    return layout, field, xy


def test_shares_start_whole_and_only_fall(tiny) -> None:
    layout, field, xy = tiny
    tol = tolerance(layout, field, xy, ScannerModel(), OPTS)
    assert tol.radii == RADII and tol.covered == field.n_cells
    # at the marks the cover is the plan's own: nothing lost, in any sense
    assert tol.worst[0] == tol.mean[0] == tol.guaranteed[0] == 1.0
    assert np.all(np.diff(tol.worst) <= 0), tol.worst
    for w, m, g in zip(tol.worst, tol.mean, tol.guaranteed, strict=True):
        assert 0.0 <= g <= w <= m <= 1.0
    # half a metre puts some stop out of the row gap's strip: faces lining it turn away
    assert tol.worst[-1] < 0.99 and tol.first_below(0.99) == RADII[-1]
    again = tolerance(layout, field, xy, ScannerModel(), OPTS)
    assert again == tol  # seeded


def test_metres_off_the_mark_see_less(tiny) -> None:
    layout, field, xy = tiny
    tol = tolerance(layout, field, xy, ScannerModel(), OPTS, radii=(0.0, 3.0))
    assert tol.worst[1] < tol.mean[1] < 1.0 and tol.guaranteed[1] < tol.worst[1]
    # 3 m runs into plots or the boundary in most directions: those stops are cut short
    assert 0.0 < tol.shortened[1] < 1.0 and tol.shortened[0] == 0.0


def test_free_run_keeps_the_robot_in_the_lanes(tiny) -> None:
    layout, field, xy = tiny
    run = free_run(layout, field, xy, 3.0)
    stops = xy[:, None, :] + run[..., None] * DIRECTIONS[None]
    # the centre stays at least the robot's half width from every plot, whatever way it faces
    boxes = field.plot_boxes
    gap = np.maximum(
        np.maximum(boxes[:, 0:2] - stops[..., None, :], stops[..., None, :] - boxes[:, 3:5]), 0
    )
    assert np.hypot(gap[..., 0], gap[..., 1]).min() >= layout.robot_half_width - 1e-9
    # an inner lane intersection, by hand: facing along the alley the robot fits until
    # it is alley/2 - half width across it, which a 45 degree move reaches at sqrt(2) x that
    inner = int(np.flatnonzero(np.all(np.isclose(xy, (6.0, 2.8)), axis=1))[0])
    diag = (layout.alley_width / 2 - layout.robot_half_width) * math.sqrt(2)
    assert diag - STEP <= run[inner, 1] <= diag
    assert run[inner, 0] == 3.0  # along the row gap nothing is in the way for 3 m
    with pytest.raises(ValueError, match="not a free robot position"):
        free_run(layout, field, field.plot_boxes[:1, [0, 1]] + 0.5, 0.1)
