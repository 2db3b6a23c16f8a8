"""Navigation's commands name their route: a CancelRoute that arrives late (it waited
behind a stalled tick, and the mission has sent the next route since) does not end the
route sent after it. The service runs in-process on a real bus."""

from __future__ import annotations

import logging
from pathlib import Path

from common.clock import WallClock
from common.messages.nav import CancelRoute, FollowRoute, Leg
from common.service import Context
from common.transport import Bus
from services.nav.config import NavConfig
from services.nav.service import build

TINY = Path(__file__).resolve().parents[1] / "data" / "tiny.toml"


def test_a_late_cancel_of_an_earlier_route_leaves_the_current_one(
    client_bus: Bus, tmp_path: Path
) -> None:
    ctx = Context(
        "nav", "test", client_bus, WallClock(), logging.getLogger("t"), tmp_path, str(TINY)
    )
    nav = build(ctx, NavConfig())
    legs = [Leg(x0=1.0, y0=1.0, x1=4.0, y1=1.0)]
    assert nav.handle(FollowRoute(route_id="m.1.0.2", legs=legs, lease_s=60)).accepted
    late = nav.handle(CancelRoute(route_id="m.1.0.1"))
    assert not late.accepted and "m.1.0.1" in late.reason
    assert nav.follower.active and nav.follower.route_id == "m.1.0.2"
    assert nav.handle(CancelRoute(route_id="m.1.0.2")).accepted
    assert not nav.follower.active
    assert nav.handle(FollowRoute(route_id="m.2", legs=legs, lease_s=60)).accepted
    assert nav.handle(CancelRoute()).accepted  # no route named: whatever is followed
    assert not nav.follower.active
