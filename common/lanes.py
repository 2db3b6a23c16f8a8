"""A field's lanes cut into segments, the unit robots sharing a field reserve.

A *lane segment* is a stretch of one lane between two neighbouring lane
intersections (:mod:`common.field`): of a cross lane between two row-gap lanes, or of
a row-gap lane between two cross lanes, as the lane graph of Open-RMF's traffic
schedule has its lanes between waypoints. Only the lanes a survey drives are cut
(:func:`driven_rows`): with ``aha`` navigation, the default, every cross lane and the
field's two edge lanes; the gaps between plot rows (0.8 m on ENGR) are no one's way,
and two robots at the two ends of one, in neighbouring alleys, are not in each
other's.

A robot is *in* a segment when its body reaches the segment's centre line: its
centre within ``radius`` of it (half the footprint's diagonal). At an intersection a
robot is in every segment that meets there, so two robots in one segment are closer
than a segment's length and one of them would have to pass the other: the
reservations (:mod:`services.mission.lanes`) keep that from happening, and the
evaluation checks it on the robots' true positions.

Robots sharing a field park off the lanes (:func:`homes`), beside the field's two
edge lanes in turn, ``PARK_M`` outside them. A robot at home is in no lane segment,
so one that has finished, or waits there, is in nobody's way. Pure.
"""

from __future__ import annotations

import math

import numpy as np

from common.arrays import F64
from common.field import Field
from common.messages.nav import Leg
from common.messages.plan import PlanResult

# how far outside the edge lane's centre line a robot of a fleet parks (m): beyond the
# reach of a Husky's body (0.6 m) and the reservations' margin
PARK_M = 1.5
# how many cross lanes apart the robots' home intersections are: at neighbouring
# intersections both robots would be in the lane segment between them
HOME_STRIDE = 2
# how finely a leg is walked to find the segments it passes (m): well under any radius
STEP_M = 0.05


class LaneMap:
    """The lane segments of ``field``: ``ids`` (``c<k>.<j>``
    cross lane k between row-gap lanes j and j+1; ``r<j>.<k>`` row-gap lane j between
    cross lanes k and k+1) and their end points ``ends`` (S, 4: x0, y0, x1, y1)."""

    def __init__(self, field: Field, rows: list[int] | None = None) -> None:
        """``rows``: the row-gap lanes driven (None: every one)."""
        xs, ys = field.cross_lanes_x, field.row_lanes_y
        ids: list[str] = []
        ends: list[tuple[float, float, float, float]] = []
        for k, x in enumerate(xs):
            for j in range(len(ys) - 1):
                ids.append(f"c{k}.{j}")
                ends.append((float(x), float(ys[j]), float(x), float(ys[j + 1])))
        for j in range(len(ys)) if rows is None else sorted(set(rows)):
            for k in range(len(xs) - 1):
                ids.append(f"r{j}.{k}")
                ends.append((float(xs[k]), float(ys[j]), float(xs[k + 1]), float(ys[j])))
        self.ids = ids
        self.ends: F64 = np.asarray(ends, dtype=np.float64).reshape(-1, 4)

    def distances(self, xy: F64) -> F64:
        """(N, S): from each point of ``xy`` (N, 2) to each segment's centre line."""
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        a, b = self.ends[:, :2], self.ends[:, 2:]
        ab = b - a
        t = ((p[:, None, :] - a[None]) * ab[None]).sum(-1) / (ab * ab).sum(-1)[None]
        closest = a[None] + np.clip(t, 0.0, 1.0)[..., None] * ab[None]
        out: F64 = np.hypot(*(p[:, None, :] - closest).transpose(2, 0, 1))
        return out

    def at(self, xy: F64, radius: float) -> list[set[str]]:
        """For each point of ``xy``, the segments a robot there is in."""
        near = self.distances(xy) <= radius
        return [{self.ids[s] for s in np.flatnonzero(row)} for row in near]

    def along(self, legs: list[Leg], radius: float) -> set[str]:
        """Every segment a robot following ``legs`` is in at some point of them."""
        pts = [np.array([[g.x0, g.y0]]) for g in legs[:1]]
        for g in legs:
            n = max(1, math.ceil(g.length / STEP_M))
            t = np.linspace(0.0, 1.0, n + 1)[1:, None]
            pts.append(np.array([g.x0, g.y0]) + t * np.array([g.x1 - g.x0, g.y1 - g.y0]))
        if not pts:
            return set()
        near = (self.distances(np.concatenate(pts)) <= radius).any(axis=0)
        return {self.ids[s] for s in np.flatnonzero(near)}


def driven_rows(nav: str, n_rows: int, open_rows: list[int] | None = None) -> list[int]:
    """The row-gap lanes (of ``n_rows``) a survey under navigation mode ``nav`` drives
    (:mod:`services.planner.route`): every one with ``br``, the two edge lanes with
    ``aha``, ``open_rows`` (default the edge lanes) with ``lanes``."""
    if nav == "br":
        return list(range(n_rows))
    if nav == "lanes" and open_rows is not None:
        return sorted(set(open_rows))
    return sorted({0, n_rows - 1})


def footprint_radius(length: float, width: float) -> float:
    """Half the diagonal of a robot's footprint: how far its body reaches from its centre."""
    return 0.5 * math.hypot(length, width)


def homes(xs: F64, ys: F64, origin: F64, robots: int, near: F64 | None = None) -> tuple[F64, F64]:
    """(access, home), each (robots, 2), for a field of cross lanes at ``xs`` and
    row-gap lanes at ``ys`` surveyed from ``origin``: the robots take the two edge
    lanes in turn, the first the Origin's and the second the opposite one, so that
    two robots enter the field's alleys from either end. On each edge lane they are
    ``HOME_STRIDE`` cross lanes apart: from the Origin's cross lane inwards, or with
    ``near`` (the survey's locations, (M, 2)) around the cross lane nearest them all
    (:func:`central_cross_lane`), so that no robot drives the length of the field
    before its first scan and after its last. Robot k's access is its intersection on
    its edge lane, its home the place ``PARK_M`` outside the field beyond it.
    ValueError, one line, when an edge lane has too few intersections for them."""
    k0 = int(np.argmin(np.abs(xs - origin[0])))
    j0 = int(np.argmin(np.abs(ys - origin[1])))
    edges = (j0, len(ys) - 1 - j0)
    per_edge = (robots + 1) // 2
    if near is None:
        inward = 1 if k0 == 0 else -1
        steps = [inward * i for i in range(per_edge)]
    else:
        k0 = central_cross_lane(xs, near)
        # around the centre as long as both sides have room, then on the side that has
        lo, hi = -(k0 // HOME_STRIDE), (len(xs) - 1 - k0) // HOME_STRIDE
        steps = sorted(range(lo, hi + 1), key=lambda i: (abs(i), -i))[:per_edge]
    ks = [k0 + HOME_STRIDE * steps[r // 2] if r // 2 < len(steps) else -1 for r in range(robots)]
    if not all(0 <= k < len(xs) for k in ks):
        raise ValueError(
            f"{robots} robots park {HOME_STRIDE} cross lanes apart along "
            f"the edge lanes, and the field has {len(xs)} cross lanes"
        )
    js = [edges[r % 2] for r in range(robots)]
    access = np.array([[xs[k], ys[j]] for k, j in zip(ks, js, strict=True)], dtype=np.float64)
    outward = np.array([[0.0, -PARK_M if j == 0 else PARK_M] for j in js])
    return access, access + outward


def parked_pose(
    home: tuple[float, float], access: tuple[float, float]
) -> tuple[float, float, float]:
    """Where a parked robot starts: (x, y, heading in degrees) at ``home``, facing
    ``access``, its way into the field."""
    facing = math.degrees(math.atan2(access[1] - home[1], access[0] - home[0]))
    return float(home[0]), float(home[1]), facing


def central_cross_lane(xs: F64, pts: F64) -> int:
    """The cross lane (of those at ``xs``) whose intersections with the edge lanes are
    nearest, in summed distance along the lanes, to the locations ``pts`` (M, 2): a
    location is reached along an edge lane, then up its own cross lane, so only the
    distance along the edge depends on the choice (ties to the lower index)."""
    cost = np.abs(xs[:, None] - pts[None, :, 0]).sum(axis=1)
    return int(np.argmin(cost))


def plan_lanes(field: Field, plan: PlanResult) -> LaneMap:
    """The lane segments of the lanes ``plan`` drives on ``field``."""
    opt = plan.options
    return LaneMap(field, driven_rows(opt.nav, len(field.row_lanes_y), opt.open_rows))
