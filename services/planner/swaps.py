"""The survey's time with its battery swaps: each location's round trip from the
Origin (the safe place a robot waits at for a swap), and the estimate of the tour
with the swaps the mission would make (:func:`common.battery.estimate`). Pure."""

from __future__ import annotations

import numpy as np

from common.arrays import F64
from common.battery import Battery, Estimate, Pace, Visit, estimate
from common.messages.nav import Leg, legs_length, round_trip_halves
from services.planner.route import Navigator
from services.planner.waypoints import tour_legs


def via_origin(nav: Navigator, origin: F64, xy: F64, ids: list[int]) -> dict[int, list[Leg]]:
    """Each location's round trip from the Origin along the lanes: the legs to it (the
    last one carries its scan id) and back."""
    out: dict[int, list[Leg]] = {}
    for p, cid in zip(xy, ids, strict=True):
        out[cid] = tour_legs(nav, np.vstack([origin, p]), [0, 1], [None, cid])
    return out


def survey_estimate(
    legs: list[Leg], via: dict[int, list[Leg]], battery: Battery, pace: Pace
) -> Estimate:
    """The tour of ``legs`` at ``pace``, with the swaps ``battery`` asks for."""
    visits: list[Visit] = []
    run: list[Leg] = []
    for g in legs:
        run.append(g)
        if g.scan_id is not None:
            there, back = round_trip_halves(via[g.scan_id])
            visits.append(Visit(legs_length(run), legs_length(there), legs_length(back)))
            run = []
    return estimate(visits, legs_length(run), battery, pace)
