"""A tour broken into straight legs along lanes (paper section 4.3.1).

Each :class:`common.messages.nav.Leg` runs from (x0, y0) to (x1, y1) in the ``field``
frame; the robot holds the leg's heading (:func:`heading`) while driving it and on
arrival rotates in place to ``final_yaw``, the heading of the next leg, as the paper's
global planner does. A leg ending at a scan location carries its ``scan_id`` and no
``final_yaw``: the robot scans in the heading it arrived with and turns when it sets
off again. A 360 deg scan does not care which way the robot faces, but a skid-steer
turn in place shifts the robot sideways by centimetres (the paper saw it at every
corner), which would move the scanner off its planned point. A scan location that
coincides with the tour's start gets a zero-length leg so it is not skipped.
"""

from __future__ import annotations

import itertools
import math

from common.arrays import F64
from common.messages.nav import Leg
from services.planner.route import Navigator


def heading(leg: Leg) -> float:
    """Heading to hold along ``leg``, radians CCW from field +x (REP-103), in (-pi, pi]."""
    return math.atan2(leg.y1 - leg.y0, leg.x1 - leg.x0)


def tour_legs(nav: Navigator, pts: F64, order: list[int], scan_ids: list[int | None]) -> list[Leg]:
    """Legs of the closed tour visiting ``pts[order]`` and returning to ``pts[order[0]]``.

    ``scan_ids[k]`` is the scan id of point k (None for the start corner).
    """
    raw: list[tuple[float, float, float, float, int | None]] = []
    stops = [*order, order[0]]
    for a, b in itertools.pairwise(stops):
        corners = nav.path(pts[a], pts[b])
        if len(corners) < 2:
            if scan_ids[b] is not None and b != order[0]:
                x, y = float(corners[0][0]), float(corners[0][1])
                raw.append((x, y, x, y, scan_ids[b]))
            continue
        for k in range(len(corners) - 1):
            sid = scan_ids[b] if k == len(corners) - 2 and b != order[0] else None
            p, q = corners[k], corners[k + 1]
            raw.append((float(p[0]), float(p[1]), float(q[0]), float(q[1]), sid))
    if scan_ids[order[0]] is not None:
        # the start point is itself a scan location: scan there before leaving
        x, y = float(pts[order[0]][0]), float(pts[order[0]][1])
        raw.insert(0, (x, y, x, y, scan_ids[order[0]]))
    yaws = [
        math.atan2(y1 - y0, x1 - x0) if (x1, y1) != (x0, y0) else None for x0, y0, x1, y1, _ in raw
    ]
    legs: list[Leg] = []
    for k, (x0, y0, x1, y1, sid) in enumerate(raw):
        nxt = None if sid is not None else next((y for y in yaws[k + 1 :] if y is not None), None)
        legs.append(Leg(x0=x0, y0=y0, x1=x1, y1=y1, final_yaw=nxt, scan_id=sid))
    return legs
