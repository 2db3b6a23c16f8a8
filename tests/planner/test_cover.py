"""Set cover: Algorithm 1 on hand-made tables, CP-SAT's minimum, the paper's fields."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp

from common.field import ScannerModel, load_field
from services.planner.cover import exact_cover, greedy_cover
from services.planner.visibility import compute_visibility


def _table(sets: list[list[int]], n_cells: int) -> sp.csr_matrix:
    rows = [j for j, s in enumerate(sets) for _ in s]
    cols = [c for s in sets for c in s]
    return sp.csr_matrix((np.ones(len(cols), bool), (rows, cols)), shape=(len(sets), n_cells))


# greedy takes S2 (4 cells) first and then needs two more; S0 + S1 is the optimum
TRAP = _table([[0, 1, 2], [3, 4, 5], [0, 1, 3, 4]], 6)


def test_greedy_follows_algorithm_1():
    c = greedy_cover(TRAP)
    assert c.selected == [2, 0, 1]
    assert (c.cells_total, c.cells_coverable, c.cells_covered) == (6, 6, 6)
    assert c.status == "greedy"


def test_greedy_ties_go_to_the_lowest_index_and_skip_useless_sets():
    c = greedy_cover(_table([[0, 1], [2, 3], [0, 1], [1]], 5))  # cell 4 never seen
    assert c.selected == [0, 1]
    assert c.cells_coverable == 4 and c.cells_covered == 4


def test_exact_beats_greedy_on_the_trap():
    c = exact_cover(TRAP, time_limit_s=5)
    assert sorted(c.selected) == [0, 1]
    assert c.status == "optimal" and c.gap == 0.0 and c.bound == 2.0


def test_coverage_target():
    sets = [[0, 1, 2, 3, 4, 5], [6, 7], [8], [9]]
    tab = _table(sets, 10)
    assert greedy_cover(tab, 0.6).selected == [0]
    assert len(exact_cover(tab, 0.8, time_limit_s=5).selected) == 2
    assert exact_cover(tab, 0.8, time_limit_s=5).cells_covered >= 8
    with pytest.raises(ValueError, match=r"coverage target=1\.5"):
        greedy_cover(tab, 1.5)


@pytest.mark.parametrize(("name", "expected"), [("engr", 11), ("spl", 7)])
def test_paper_fields(name: str, expected: int):
    _, field = load_field(name)
    vis = compute_visibility(field, ScannerModel()).matrix()
    greedy = greedy_cover(vis)
    exact = exact_cover(vis, time_limit_s=20, hint=greedy)
    assert field.n_candidates == 77
    assert len(exact.selected) <= len(greedy.selected)
    assert exact.status == "optimal"
    for c in (greedy, exact):
        assert c.cells_covered == c.cells_coverable == field.n_cells
        assert (np.asarray(vis[c.selected].sum(axis=0)).ravel() > 0).all()
    # the paper's counts (ENGR 11: one location per row-gap lane is a hard bound there)
    assert len(exact.selected) == expected
    if name == "engr":
        rows = sorted(field.cand_row_lane[exact.selected].tolist())
        assert rows == list(range(11))


def test_exact_cover_is_the_same_on_every_run():
    # a ring of cells, each seen by three neighbouring candidates: thousands of covers
    # of the fewest locations, of which the solver must always return the same one
    n = 60
    rows = np.concatenate([np.arange(n), np.arange(n), np.arange(n)])
    cols = np.concatenate([np.arange(n), (np.arange(n) + 1) % n, (np.arange(n) + 2) % n])
    vis = sp.csr_matrix((np.ones(3 * n, dtype=bool), (rows, cols)), shape=(n, n))
    worse = dataclasses.replace(greedy_cover(vis), selected=list(range(0, n, 2)))
    runs = {tuple(exact_cover(vis, time_limit_s=30, hint=worse).selected) for _ in range(5)}
    assert len(runs) == 1
    assert len(next(iter(runs))) == n // 3
