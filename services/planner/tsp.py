"""Closed tours through node 0 (the start corner) over a distance matrix (metres).

- :func:`circuit_cpsat`: CP-SAT with a circuit constraint, proven optimal when it
  finishes inside its time limit (a field's few dozen locations: in well under a
  second);
- :func:`guided_local_search`: OR-Tools routing with GUIDED_LOCAL_SEARCH, for large tours;
- :func:`nearest_neighbour`: the paper's baseline.

Every solver returns a :class:`Tour` whose ``order`` starts at node 0 and does not
repeat it at the end.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from typing import Any

import numba as nb
import numpy as np
from ortools.constraint_solver import pywrapcp, routing_enums_pb2
from ortools.sat.python import cp_model

from common.arrays import F64

log = logging.getLogger(__name__)

CPSAT_MAX = 80
# integer arc costs for the OR-Tools solvers, in millimetres
_SCALE = 1000.0


@dataclasses.dataclass(frozen=True)
class Tour:
    """``status``: ``"optimal"`` (proven) or ``"heuristic"``."""

    order: list[int]
    length: float
    method: str
    status: str
    time_s: float


def tour_length(d: F64, order: list[int]) -> float:
    """Length of the closed tour ``order`` (back to its first node)."""
    idx = np.asarray(order + order[:1])
    return float(d[idx[:-1], idx[1:]].sum())


def _check(d: F64) -> F64:
    d = np.asarray(d, dtype=np.float64)
    if d.ndim != 2 or d.shape[0] != d.shape[1] or d.shape[0] == 0:
        raise ValueError(f"distance matrix: expected a non-empty square array, got {d.shape}")
    if not np.all(np.isfinite(d)) or np.any(d < 0):
        raise ValueError("distance matrix: entries must be finite and >= 0 (unreachable node?)")
    return d


def _start(d: F64, method: str) -> tuple[float, F64, Tour | None]:
    """A solver's start: its clock, the checked matrix and, for at most three nodes
    (every order is then optimal), the tour itself."""
    t0 = time.perf_counter()
    d = _check(d)
    n = d.shape[0]
    if n > 3:
        return t0, d, None
    order = list(range(n))
    return t0, d, Tour(order, tour_length(d, order), method, "optimal", time.perf_counter() - t0)


def nearest_neighbour(d: F64) -> Tour:
    """Always go to the nearest unvisited node (ties: lowest index), then home."""
    t0 = time.perf_counter()
    d = _check(d)
    n = d.shape[0]
    left = np.ones(n, dtype=bool)
    left[0] = False
    order = [0]
    for _ in range(n - 1):
        row = np.where(left, d[order[-1]], np.inf)
        j = int(np.argmin(row))
        order.append(j)
        left[j] = False
    return Tour(
        order, tour_length(d, order), "nearest-neighbour", "heuristic", time.perf_counter() - t0
    )


def circuit_cpsat(
    d: F64, time_limit_s: float = 10.0, hint: list[int] | None = None, seed: int = 0
) -> Tour:
    """CP-SAT over arc literals with ``add_circuit``; ``status`` is ``"optimal"`` only
    when CP-SAT proves it. Raises RuntimeError when no tour is found in time."""
    t0, d, trivial = _start(d, "cp-sat-circuit")
    if trivial is not None:
        return trivial
    n = d.shape[0]
    cost = np.rint(d * _SCALE).astype(np.int64)
    m = cp_model.CpModel()
    arcs: dict[tuple[int, int], cp_model.IntVar] = {}
    for i in range(n):
        for j in range(n):
            if i != j:
                arcs[i, j] = m.new_bool_var(f"a{i}_{j}")
    m.add_circuit([(i, j, v) for (i, j), v in arcs.items()])
    m.minimize(sum(int(cost[i, j]) * v for (i, j), v in arcs.items()))
    if hint is not None:
        nxt = {a: b for a, b in zip(hint, hint[1:] + hint[:1], strict=True)}
        for (i, j), v in arcs.items():
            m.add_hint(v, nxt.get(i) == j)
    solver = cp_model.CpSolver()
    solver.parameters.max_time_in_seconds = float(time_limit_s)
    solver.parameters.num_workers = 8  # full portfolio; see cover.py
    solver.parameters.random_seed = seed
    solver.parameters.interleave_search = True  # the same tour on every run; see cover.py
    code = solver.solve(m)
    if code not in (cp_model.OPTIMAL, cp_model.FEASIBLE):
        raise RuntimeError(f"CP-SAT found no tour of {n} nodes in {time_limit_s} s")
    succ = {i: j for (i, j), v in arcs.items() if solver.value(v)}
    order = [0]
    while len(order) < n:
        order.append(succ[order[-1]])
    status = "optimal" if code == cp_model.OPTIMAL else "heuristic"
    return Tour(order, tour_length(d, order), "cp-sat-circuit", status, time.perf_counter() - t0)


def gls_parameters(time_limit_s: float) -> Any:
    """OR-Tools routing's search: the cheapest arc first, then guided local search
    until ``time_limit_s`` (it runs to the limit, however small the problem)."""
    params = pywrapcp.DefaultRoutingSearchParameters()
    params.first_solution_strategy = routing_enums_pb2.FirstSolutionStrategy.PATH_CHEAPEST_ARC
    params.local_search_metaheuristic = (
        routing_enums_pb2.LocalSearchMetaheuristic.GUIDED_LOCAL_SEARCH
    )
    params.time_limit.FromMilliseconds(max(1, int(time_limit_s * 1000)))
    return params


def guided_local_search(d: F64, time_limit_s: float = 10.0) -> Tour:
    """OR-Tools routing: PATH_CHEAPEST_ARC then GUIDED_LOCAL_SEARCH until the limit."""
    t0, d, trivial = _start(d, "guided-local-search")
    if trivial is not None:
        return trivial
    n = d.shape[0]
    cost = np.rint(d * _SCALE).astype(np.int64).tolist()
    manager = pywrapcp.RoutingIndexManager(n, 1, 0)
    routing = pywrapcp.RoutingModel(manager)
    cb = routing.RegisterTransitMatrix(cost)
    routing.SetArcCostEvaluatorOfAllVehicles(cb)
    sol = routing.SolveWithParameters(gls_parameters(time_limit_s))
    if sol is None:
        raise RuntimeError(f"OR-Tools routing found no tour of {n} nodes")
    order: list[int] = []
    idx = routing.Start(0)
    while not routing.IsEnd(idx):
        order.append(manager.IndexToNode(idx))
        idx = sol.Value(routing.NextVar(idx))
    return Tour(
        order, tour_length(d, order), "guided-local-search", "heuristic", time.perf_counter() - t0
    )


def one_tree_bound(d: F64, upper: float, iterations: int = 1000) -> float:
    """A lower bound on the shortest closed tour over ``d``: Held and Karp's 1-tree
    bound (1970, Operations Research 18:1138), the node penalties raised by
    subgradient steps towards the tour length ``upper`` (Held, Wolfe & Crowder 1974,
    Mathematical Programming 6:62). Every tour is a 1-tree (a spanning tree of the
    nodes but 0, and two edges at 0) with every degree 2, so the cheapest 1-tree under
    any penalties, less twice their sum, is at most the shortest tour. An asymmetric
    ``d`` is bounded by its cheaper direction per pair."""
    d = _check(d)
    n = d.shape[0]
    if n <= 3:
        return tour_length(d, list(range(n)))
    return float(_held_karp_bound(np.minimum(d, d.T), float(upper), iterations))


@nb.njit(cache=True)
def _held_karp_bound(w0: F64, upper: float, iterations: int) -> float:  # pragma: no cover  # noqa: C901
    n = w0.shape[0]
    pi = np.zeros(n)
    best, lam, since = -np.inf, 2.0, 0
    deg = np.zeros(n, dtype=np.int64)
    key = np.empty(n)
    parent = np.empty(n, dtype=np.int64)
    done = np.empty(n, dtype=np.bool_)
    for _ in range(iterations):
        # Prim's minimum spanning tree of nodes 1..n-1 under the penalised weights
        deg[:] = 0
        key[:] = np.inf
        done[:] = False
        key[1] = 0.0
        parent[1] = -1
        length = 0.0
        for _k in range(n - 1):
            u, ku = -1, np.inf
            for v in range(1, n):
                if not done[v] and key[v] < ku:
                    u, ku = v, key[v]
            done[u] = True
            if parent[u] >= 0:
                length += ku
                deg[u] += 1
                deg[parent[u]] += 1
            for v in range(1, n):
                if not done[v]:
                    wv = w0[u, v] + pi[u] + pi[v]
                    if wv < key[v]:
                        key[v], parent[v] = wv, u
        # node 0's two cheapest edges
        a, b, wa, wb = -1, -1, np.inf, np.inf
        for v in range(1, n):
            wv = w0[0, v] + pi[0] + pi[v]
            if wv < wa:
                b, wb, a, wa = a, wa, v, wv
            elif wv < wb:
                b, wb = v, wv
        length += wa + wb
        deg[0] = 2
        deg[a] += 1
        deg[b] += 1
        bound = length - 2.0 * pi.sum()
        if bound > best + 1e-9:
            best, since = bound, 0
        else:
            since += 1
            if since >= 30:  # no progress: smaller steps
                lam, since = lam / 2.0, 0
        norm = 0.0
        for v in range(n):
            norm += (deg[v] - 2.0) ** 2
        if norm == 0.0 or lam < 1e-6:  # a 1-tree that is a tour is the optimum
            break
        step = lam * max(upper - bound, 1e-9) / norm
        for v in range(n):
            pi[v] += step * (deg[v] - 2.0)
    return best


def solve_tour(d: F64, method: str = "auto", time_limit_s: float = 10.0) -> Tour:
    """Best tour by ``method``: ``"cp-sat"``, ``"gls"`` or ``"auto"`` (CP-SAT up to 80
    nodes, falling back to GLS if it finds no tour in time, GLS beyond). Raises
    ValueError on an unknown method."""
    d = _check(d)
    n = d.shape[0]
    if method == "gls" or (method == "auto" and n > CPSAT_MAX):
        return guided_local_search(d, time_limit_s)
    if method not in ("cp-sat", "auto"):
        raise ValueError(f"tour method {method!r}: expected auto, cp-sat or gls")
    nn = nearest_neighbour(d)
    try:
        tour = circuit_cpsat(d, time_limit_s, hint=nn.order)
    except RuntimeError:
        log.warning("CP-SAT tour timed out on %d nodes; using guided local search", n)
        return guided_local_search(d, time_limit_s)
    return tour
