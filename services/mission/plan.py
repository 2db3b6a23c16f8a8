"""From a plan to mission steps: which legs lead to which scan location. Pure."""

from __future__ import annotations

import dataclasses
import math

from common.messages.nav import Leg
from common.messages.plan import PlanResult


@dataclasses.dataclass(frozen=True)
class Segment:
    """The legs that lead to one scan location (``cand_id``), or home (None)."""

    cand_id: int | None
    legs: list[Leg]

    @property
    def end(self) -> tuple[float, float, float | None]:
        last = self.legs[-1]
        yaw = last.final_yaw
        if yaw is None and (last.x1 != last.x0 or last.y1 != last.y0):
            yaw = math.atan2(last.y1 - last.y0, last.x1 - last.x0)
        return last.x1, last.y1, yaw


def segments(plan: PlanResult) -> list[Segment]:
    """The plan's legs cut at each scan location; a final segment returns home.

    Raises ValueError when the plan's legs and selected locations disagree."""
    out: list[Segment] = []
    cur: list[Leg] = []
    for leg in plan.legs:
        cur.append(leg)
        if leg.scan_id is not None:
            out.append(Segment(leg.scan_id, cur))
            cur = []
    if cur:
        out.append(Segment(None, cur))
    scanned = [s.cand_id for s in out if s.cand_id is not None]
    if sorted(scanned) != sorted(plan.selected):
        raise ValueError(f"plan: legs end at locations {scanned}, but selected are {plan.selected}")
    return out
