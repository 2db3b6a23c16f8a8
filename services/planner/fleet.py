"""The chosen locations split between several robots so that the slowest finishes
first: OR-Tools routing with one vehicle per robot, each leaving from and returning to
its own lane intersection (:func:`common.lanes.homes`), on a time dimension (the lane distance at
the survey's pace, plus each location's time) whose global span is the cost to
minimise. Pure.

The split balances time, not distance: a location costs its positioning and scan
whoever takes it, so a robot with the far locations takes fewer of them.

Each robot of a fleet parks off the lanes (:func:`common.lanes.homes`), so one that
has finished, or waits there, never stands in another's way; its tour starts and
ends with the short leg between its home and its intersection."""

from __future__ import annotations

import dataclasses
import itertools
import math
import time

import numpy as np
from ortools.constraint_solver import pywrapcp

from common.arrays import F64
from common.battery import Battery, Pace
from common.lanes import homes
from common.messages.nav import Leg
from common.messages.plan import Fleet, FleetPart, PlanOptions
from services.planner.route import Navigator
from services.planner.swaps import survey_estimate
from services.planner.tsp import gls_parameters, solve_tour
from services.planner.waypoints import tour_legs

# routing works in integers: deciseconds
_SCALE = 10.0
# the weight of the span (the slowest robot's time) against the sum of times: large, so
# the span comes first and the total breaks its ties
SPAN_WEIGHT = 100


@dataclasses.dataclass(frozen=True)
class Split:
    """``orders[r]``: robot r's tour as node indices, its depot first;
    ``times_s[r]``: its time at ``pace``; ``status``: ``heuristic`` (guided local
    search to its time limit), ``trivial``, or one robot's tour's own
    (:func:`services.planner.tsp.solve_tour`)."""

    orders: list[list[int]]
    times_s: list[float]
    status: str
    time_s: float

    @property
    def makespan_s(self) -> float:
        return max(self.times_s)


def tour_time(d: F64, order: list[int], pace: Pace) -> float:
    """The closed tour ``order`` (from its first node and back) at ``pace``."""
    stops = [*order, order[0]]
    metres = sum(float(d[a, b]) for a, b in itertools.pairwise(stops))
    return pace.drive_s(metres) + pace.location_s * (len(order) - 1)


def split_tours(
    d: F64, robots: int, pace: Pace, time_limit_s: float = 10.0, depots: int = 1
) -> Split:
    """Tours of ``robots`` robots over the nodes of ``d`` minimising the slowest one's
    time. The first ``depots`` nodes are where tours start and end: node 0 for every
    robot, or with ``depots == robots`` node r for robot r; every other node is a
    location visited by exactly one robot. Raises ValueError when there are more
    robots than locations."""
    t0 = time.perf_counter()
    n = d.shape[0]
    if depots not in (1, robots):
        raise ValueError(f"{depots} depots for {robots} robots: one, or one a robot")
    if robots < 1 or robots > n - depots:
        raise ValueError(
            f"{robots} robots for {n - depots} locations: at most one robot a location"
        )
    if n <= 2:
        order = list(range(n))
        return Split([order], [tour_time(d, order, pace)], "trivial", time.perf_counter() - t0)
    if robots == 1:  # every location costs the same time: the shortest tour is the fastest
        tour = solve_tour(d, "auto", time_limit_s)
        order = tour.order
        return Split([order], [tour_time(d, order, pace)], tour.status, time.perf_counter() - t0)
    at = np.full(n, pace.location_s)
    at[:depots] = 0.0
    # the time of an arc: the drive, then the location's time at its end
    cost = np.rint((d / pace.speed + at[None, :]) * _SCALE).astype(np.int64).tolist()
    ends = list(range(robots)) if depots > 1 else [0] * robots
    manager = pywrapcp.RoutingIndexManager(n, robots, ends, ends)
    routing = pywrapcp.RoutingModel(manager)
    cb = routing.RegisterTransitMatrix(cost)
    routing.SetArcCostEvaluatorOfAllVehicles(cb)
    horizon = int(sum(max(row) for row in cost)) + 1
    routing.AddDimension(cb, 0, horizon, True, "time")
    routing.GetDimensionOrDie("time").SetGlobalSpanCostCoefficient(SPAN_WEIGHT)
    sol = routing.SolveWithParameters(gls_parameters(time_limit_s))
    if sol is None:
        raise RuntimeError(f"OR-Tools routing split no tours for {robots} robots")
    orders: list[list[int]] = []
    for r in range(robots):
        idx, order = routing.Start(r), []
        while not routing.IsEnd(idx):
            order.append(manager.IndexToNode(idx))
            idx = sol.Value(routing.NextVar(idx))
        orders.append(order)
    times = [tour_time(d, o, pace) if len(o) > 1 else 0.0 for o in orders]
    return Split(orders, times, "heuristic", time.perf_counter() - t0)


def check_lanes(nav: Navigator, robots: int) -> None:
    """Refuse more robots than the field has lanes (its row-gap and cross lanes): with
    fewer, some would stand in another's lane whatever the split."""
    lanes = len(nav.xs) + len(nav.ys)
    if robots > lanes:
        raise ValueError(
            f"PlanOptions.robots: {robots} robots for a field of {lanes} lanes; at most "
            "one robot a lane"
        )


def _with_home(legs: list[Leg], home: F64) -> list[Leg]:
    """``legs`` (a closed tour from a home intersection) from and back to ``home``."""
    hx, hy = float(home[0]), float(home[1])
    if not legs:
        return []
    first, last = legs[0], legs[-1]
    out_yaw = math.atan2(first.y1 - first.y0, first.x1 - first.x0) if first.length else None
    back_yaw = math.atan2(last.y1 - hy, last.x1 - hx)  # parked facing its intersection
    return [
        Leg(x0=hx, y0=hy, x1=first.x0, y1=first.y0, final_yaw=out_yaw),
        *legs,
        Leg(x0=last.x1, y0=last.y1, x1=hx, y1=hy, final_yaw=back_yaw),
    ]


def fleet(
    nav: Navigator,
    pts: F64,
    ids: list[int | None],
    via: dict[int, list[Leg]],
    battery: Battery,
    opt: PlanOptions,
    one_robot_s: float,
) -> Fleet:
    """The survey of ``pts`` (the Origin first) split between ``opt.robots`` robots,
    each from and back to its home (:func:`common.lanes.homes`; by the Origin's corner,
    or with ``opt.home`` ``near`` by the locations), each part's legs and time with its
    swaps. One robot parked by its locations is a fleet of one."""
    check_lanes(nav, opt.robots)
    near = pts[1:] if opt.home == "near" else None
    access, parked = homes(nav.xs, nav.ys, pts[0], opt.robots, near)
    n = opt.robots
    pts = np.vstack([access, pts[1:]])
    ids = [*([None] * n), *ids[1:]]
    # guided local search runs to its limit, however small the problem: a second and a
    # tenth of a second a location, at most the tour's own limit
    limit = min(opt.tour_time_limit_s, 1.0 + 0.1 * (len(pts) - n))
    split = split_tours(nav.distances(pts), n, opt.pace, limit, depots=n)
    parts = []
    for r, order in enumerate(split.orders):
        legs = tour_legs(nav, pts, order, ids) if len(order) > 1 else []
        legs = _with_home(legs, parked[r])
        parts.append(
            FleetPart(
                robot=r + 1,
                order=[0 if k < n else int(ids[k] or 0) for k in order] + [0],
                legs=legs,
                survey=survey_estimate(legs, via, battery, opt.pace),
                home=(float(parked[r][0]), float(parked[r][1])),
            )
        )
    return Fleet(parts=parts, one_robot_s=one_robot_s, status=split.status, time_s=split.time_s)
