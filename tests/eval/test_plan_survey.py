"""Scoring plans on the simulator's true foliage, on the tiny field's default world."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from common.field import load_field
from phenorover.eval.plan_survey import compare_plans, true_cells, truly_seen_cells
from services.sim.render import ScanSettings
from services.sim.world import World

TINY = Path(__file__).parents[1] / "data" / "tiny.toml"
COARSE = ScanSettings(step_deg=2.0)  # fast; the figures only need some foliage hits


@pytest.fixture(scope="module")
def world() -> World:
    layout, field = load_field(TINY)
    return World(layout, field)


def test_true_cells_are_the_planner_cells_with_foliage(world: World) -> None:
    truth = true_cells(world)
    # the default plants fill most of every nominal box, but not its corners' tops
    assert 0.8 * world.field.n_cells < truth.size <= world.field.n_cells
    assert np.all(np.diff(truth) > 0)


def test_truly_seen_cells(world: World) -> None:
    xy = world.field.cand_xy
    one_seen, total = truly_seen_cells(world, xy[:1], COARSE)
    assert 0 < one_seen <= total == true_cells(world).size
    # a location on the far side adds cells the first could not see
    far = xy[np.argmax(np.hypot(*(xy - xy[0]).T))]
    two_seen, total2 = truly_seen_cells(world, np.vstack([xy[0], far]), COARSE)
    assert total2 == total and one_seen < two_seen <= total


def test_compare_plans_shares_locations(world: World) -> None:
    xy = world.field.cand_xy
    out = compare_plans(world, xy[:1], xy[:2], COARSE)
    assert out["nominal"]["locations"] == 1 and out["measured"]["locations"] == 2
    assert 0 < out["nominal"]["cells_seen"] <= out["measured"]["cells_seen"]
    assert out["measured"]["cells_seen"] <= out["cells_total"]
    assert out["nominal"]["share"] == out["nominal"]["cells_seen"] / out["cells_total"]
