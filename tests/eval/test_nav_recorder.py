"""What nav-test records: true poses paired with navigation's progress by the sim
clock's stamps, up to the route's end."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from common.messages.nav import NavProgress, NavState
from common.messages.sim import TruthPose
from phenorover.eval.nav_recorder import Recorder


class Subscriptions:
    """The one call a Recorder makes of its bus."""

    def __init__(self) -> None:
        self.handlers: dict[str, Callable[[Any], None]] = {}

    def subscribe(self, key: Any, handler: Callable[[Any], None]) -> None:
        self.handlers[str(key)] = handler


def truth(s: float) -> TruthPose:
    return TruthPose(stamp_ns=int(s * 1e9), x=s, y=0.0, z=0.0)


def progress(s: float, state: NavState, route: str = "border", leg: int = 0) -> NavProgress:
    return NavProgress(stamp_ns=int(s * 1e9), route_id=route, state=state, leg=leg)


def test_poses_pair_with_the_progress_stamped_by_then_whatever_the_arrival_order() -> None:
    rec = Recorder(Subscriptions())  # type: ignore[arg-type]
    # as two processes' messages of one instant may arrive: the truth of 0.2 s before
    # the progress of 0.1 s, the progress of 0.3 s before the truth of 0.3 s
    rec._progress(progress(0.0, NavState.NOT_LOCALIZED, route="other"))
    rec._truth(truth(0.05))
    rec._truth(truth(0.2))
    rec._progress(progress(0.1, NavState.ROTATING))
    rec._progress(progress(0.3, NavState.DRIVING, leg=1))
    rec._truth(truth(0.3))
    rec._progress(progress(0.4, NavState.ARRIVED, leg=1))
    rec._truth(truth(0.4))
    rec._truth(truth(0.5))  # after the end: still standing, still heard
    pairs = [(t.stamp_ns / 1e9, p.state, p.leg) for t, p in rec.paired("border")]
    assert pairs == [
        (0.2, NavState.ROTATING, 0),
        (0.3, NavState.DRIVING, 1),
        (0.4, NavState.ARRIVED, 1),
    ]
