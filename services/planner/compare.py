"""The paper's comparison of navigation modes: the shortest tour over a plan's
locations under each way of driving between them (``br``, ``aha``, ``lanes``;
:mod:`services.planner.route`). It is not part of planning, which drives by one mode:
``phenorover plan`` prints it beside a plan of a field's dozen locations, where each
optimum is proven in a fraction of a second."""

from __future__ import annotations

import numpy as np

from common.field import Field
from common.messages.plan import PlanResult
from services.planner.route import NAV_MODES, Navigator
from services.planner.tsp import circuit_cpsat

# the most locations (the Origin included) the comparison is made for
MAX_NODES = 14


def comparable(result: PlanResult) -> bool:
    """Whether the comparison is made for ``result``: at most ``MAX_NODES`` locations
    with the Origin."""
    return len(result.selected) + 1 <= MAX_NODES


def lengths_by_nav(fld: Field, result: PlanResult) -> dict[str, float]:
    """The optimal tour length (m) over ``result``'s locations and the Origin under
    each navigation mode, with the plan's open lanes (the plan's own mode: its tour);
    a mode whose optimum is not proven within the plan's tour time limit is left out,
    and all are beyond ``MAX_NODES``."""
    if not comparable(result):
        return {}
    index = {int(c): k for k, c in enumerate(fld.cand_ids)}
    pts = np.vstack([fld.origin_xy[None, :], fld.cand_xy[[index[c] for c in result.selected]]])
    opt = result.options
    out: dict[str, float] = {}
    for mode in NAV_MODES:
        if mode == result.tour.nav and result.tour.status == "optimal":
            out[mode] = result.tour.length
            continue
        d = Navigator(fld, mode, opt.open_rows, opt.open_cross).distances(pts)
        tour = circuit_cpsat(d, opt.tour_time_limit_s)
        if tour.status == "optimal":
            out[mode] = tour.length
    return out
