"""Choosing scan locations: greedy set cover (the paper's Algorithm 1) and the exact
minimum set cover with OR-Tools CP-SAT.

Both take a boolean (candidates x cells) CSR matrix of who sees what (already thresholded
by the minimum hit count) and cover ``ceil(target * coverable)`` cells, where coverable
cells are those some candidate sees. Candidates are referred to by row index here; the
pipeline maps them to ids.
"""

from __future__ import annotations

import dataclasses
import heapq
import logging
import math
import time

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
from ortools.sat.python import cp_model

from common.arrays import I64

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class Cover:
    """A chosen set of candidates. ``status``: ``"greedy"``, ``"optimal"`` (proven),
    ``"feasible"`` (time limit hit; ``gap`` = (objective - bound) / objective) or
    ``"greedy-fallback"`` (CP-SAT found nothing in time)."""

    selected: list[int]  # candidate row indices, in the order chosen
    cells_total: int
    cells_coverable: int
    cells_target: int
    cells_covered: int
    status: str
    bound: float
    gap: float
    time_s: float


def _target(vis: sp.csr_matrix, target: float) -> tuple[npt.NDArray[np.bool_], int]:
    if not 0.0 < target <= 1.0:
        raise ValueError(f"coverage target={target}: expected a fraction in (0, 1]")
    coverable = np.asarray(vis.sum(axis=0)).ravel() > 0
    return coverable, math.ceil(target * int(coverable.sum()) - 1e-9)


def greedy_cover(vis: sp.csr_matrix, target: float = 1.0) -> Cover:
    """Algorithm 1: repeatedly take the candidate seeing the most uncovered cells (ties:
    lowest index) until the target is met.

    Evaluated lazily (scores only fall, so a popped candidate whose fresh score still
    beats the heap top is the true argmax): the same picks as the plain loop.
    """
    t0 = time.perf_counter()
    vis = sp.csr_matrix(vis, dtype=bool)
    coverable, need = _target(vis, target)
    covered = np.zeros(vis.shape[1], dtype=bool)
    n_cov = 0
    indptr, indices = vis.indptr, vis.indices
    heap = [(-(int(indptr[j + 1] - indptr[j])), j) for j in range(vis.shape[0])]
    heapq.heapify(heap)
    chosen: list[int] = []
    while n_cov < need and heap:
        _, j = heapq.heappop(heap)
        cols = indices[indptr[j] : indptr[j + 1]]
        fresh = int(np.count_nonzero(~covered[cols]))
        if fresh == 0:
            continue
        if heap and (-fresh, j) > heap[0]:
            heapq.heappush(heap, (-fresh, j))
            continue
        chosen.append(j)
        covered[cols] = True
        n_cov += fresh
    return Cover(
        selected=chosen,
        cells_total=int(vis.shape[1]),
        cells_coverable=int(coverable.sum()),
        cells_target=need,
        cells_covered=n_cov,
        status="greedy",
        bound=float("nan"),
        gap=float("nan"),
        time_s=time.perf_counter() - t0,
    )


def _unique_columns(vis: sp.csr_matrix) -> tuple[list[I64], I64]:
    """Distinct non-empty candidate sets over the cells, with how many cells share each."""
    csc = sp.csr_matrix(vis.T, dtype=bool)
    csc.sort_indices()
    seen: dict[bytes, int] = {}
    sets: list[I64] = []
    weight: list[int] = []
    for c in range(csc.shape[0]):
        rows = csc.indices[csc.indptr[c] : csc.indptr[c + 1]]
        if rows.size == 0:
            continue
        key = rows.tobytes()
        k = seen.get(key)
        if k is None:
            seen[key] = len(sets)
            sets.append(rows.astype(np.int64))
            weight.append(1)
        else:
            weight[k] += 1
    return sets, np.array(weight, dtype=np.int64)


def exact_cover(
    vis: sp.csr_matrix,
    target: float = 1.0,
    *,
    time_limit_s: float = 30.0,
    hint: Cover | None = None,
    workers: int | None = None,
    seed: int = 0,
) -> Cover:
    """Minimum number of candidates covering the target, by CP-SAT (cells with the
    same candidate set merged into one constraint), warm-started from ``hint`` (the
    greedy cover when None)."""
    t0 = time.perf_counter()
    vis = sp.csr_matrix(vis, dtype=bool)
    coverable, need = _target(vis, target)
    hint = hint if hint is not None else greedy_cover(vis, target)
    sets, weight = _unique_columns(vis)
    m = cp_model.CpModel()
    x = [m.new_bool_var(f"x{j}") for j in range(vis.shape[0])]
    if need >= int(weight.sum()):
        for s in sets:
            m.add_bool_or([x[j] for j in s])
    else:
        y = [m.new_bool_var(f"y{k}") for k in range(len(sets))]
        for yk, s in zip(y, sets, strict=True):
            m.add_bool_or([x[j] for j in s] + [yk.Not()])
        m.add(sum(int(w) * yk for w, yk in zip(weight, y, strict=True)) >= need)
    m.minimize(sum(x))
    picked = set(hint.selected)
    for j, xj in enumerate(x):
        m.add_hint(xj, j in picked)
    solver = cp_model.CpSolver()
    solver.parameters.max_time_in_seconds = float(time_limit_s)
    # CP-SAT needs its full portfolio (lower-bound workers among them) to prove
    # optimality; with 1-2 workers it stalls even on tiny covers, whatever the core count.
    solver.parameters.num_workers = workers or 8
    solver.parameters.random_seed = seed
    # The workers' portfolio in deterministic batches: a field has many covers of the
    # fewest locations, and the one a free-running portfolio returns depends on which
    # thread gets there first (and with it the tour). A cover proven optimal within
    # the time limit is then the same on every run and under any load.
    solver.parameters.interleave_search = True
    code = solver.solve(m)
    if code not in (cp_model.OPTIMAL, cp_model.FEASIBLE):
        log.warning("CP-SAT found no cover in %.1f s; keeping the greedy one", time_limit_s)
        return dataclasses.replace(hint, status="greedy-fallback", time_s=time.perf_counter() - t0)
    chosen = [j for j, xj in enumerate(x) if solver.value(xj)]
    if len(chosen) >= len(hint.selected):
        # No smaller cover: keep the hint's picks, which (unlike a parallel CP-SAT
        # search) are the same on every run.
        chosen = list(hint.selected)
    covered = np.asarray(vis[chosen].sum(axis=0)).ravel() > 0
    obj, bound = float(solver.objective_value), float(solver.best_objective_bound)
    return Cover(
        selected=chosen,
        cells_total=int(vis.shape[1]),
        cells_coverable=int(coverable.sum()),
        cells_target=need,
        cells_covered=int(covered.sum()),
        status="optimal" if code == cp_model.OPTIMAL else "feasible",
        bound=bound,
        gap=0.0 if code == cp_model.OPTIMAL else (obj - bound) / max(obj, 1.0),
        time_s=time.perf_counter() - t0,
    )
