"""Navigation's route commands (``rpc/nav/cmd``): follow a route checked against the
field, renew its lease, cancel it; each against the follower, under the service's lock."""

from __future__ import annotations

import threading

import numpy as np
import numpy.typing as npt

from common.messages.nav import CancelRoute, FollowRoute, Leg, NavCommand, NavReply, RenewRoute
from common.service import Context
from services.nav.follower import Follower


class Routes:
    """The commands of ``follower``; a route may reach ``margin_m`` beyond the field's
    ``bounds`` (x0, y0, x1, y1; m) and no further."""

    def __init__(
        self,
        follower: Follower,
        lock: threading.Lock,
        bounds: npt.NDArray[np.float64],
        margin_m: float,
        ctx: Context,
    ) -> None:
        self.follower, self._lock, self.margin_m = follower, lock, margin_m
        self.route_box = bounds + np.array([-margin_m, -margin_m, margin_m, margin_m])
        self.field, self.log = ctx.field, ctx.log

    def handle(self, cmd: NavCommand, now: int) -> NavReply:
        """Carry ``cmd`` out at ``now`` (ns, the service clock)."""
        t = now / 1e9
        with self._lock:
            match cmd:
                case FollowRoute(route_id=rid, legs=legs, max_speed=vmax, lease_s=lease):
                    if why := self._off_field(legs):
                        self.log.warning("route %s refused: %s", rid, why)
                        return NavReply(stamp_ns=now, accepted=False, reason=why)
                    self.follower.start(
                        rid, legs, vmax, t + lease, cmd.join, cmd.arrival_tolerance_m, cmd.to_scan
                    )
                    self.log.info(
                        "route %s: %d legs, from leg %d", rid, len(legs), self.follower.leg
                    )
                case RenewRoute(route_id=rid, lease_s=lease):
                    if not self.follower.renew(rid, t + lease):
                        return self._not_followed(rid, now)
                case CancelRoute(route_id=rid):
                    # a cancel names its route: one that arrives late (it waited behind
                    # a stalled tick) must not end the route sent after it
                    if rid and rid != self.follower.route_id:
                        return self._not_followed(rid, now)
                    self.follower.cancel()
                    self.log.info("route %s cancelled", self.follower.route_id)
        return NavReply(stamp_ns=now, accepted=True)

    def _not_followed(self, rid: str, now: int) -> NavReply:
        """The refusal of a command naming a route other than the one followed."""
        f = self.follower
        why = f"route {rid} is not being followed (now: {f.route_id or 'none'}, {f.state})"
        return NavReply(stamp_ns=now, accepted=False, reason=why)

    def _off_field(self, legs: list[Leg]) -> str:
        """Why the route is refused ("" if it is not): a leg ending more than
        ``route_margin_m`` outside the field's boundary."""
        x0, y0, x1, y1 = self.route_box
        for k, lg in enumerate(legs):
            for x, y in ((lg.x0, lg.y0), (lg.x1, lg.y1)):
                if not (x0 <= x <= x1 and y0 <= y <= y1):
                    return (
                        f"leg {k} reaches ({x:.6g}, {y:.6g}) m, more than "
                        f"{self.margin_m:g} m outside field {self.field}"
                    )
        return ""
