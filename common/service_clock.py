"""A service's clock, chosen by the runner (:mod:`common.service`): the wall's, the
simulator's followed, or the simulator's in lockstep (:mod:`common.lockstep`)."""

from __future__ import annotations

import contextlib
from typing import Literal

import zenoh

from common import keys
from common.clock import Clock, SimClock, WallClock
from common.config import Manifest
from common.lockstep import LockstepClock
from common.mailbox import Inbox
from common.messages.sim import ClockAck
from common.transport import Bus, key_intersects

Lockstep = Literal["participant", "observer", "world"]


def service_clock(
    bus: Bus, lockstep: Lockstep, kind: str, manifest: Manifest | None
) -> tuple[Clock, Inbox | None]:
    """The service's clock: the wall's; the simulator's, followed (an ``observer``,
    such as the dashboard, or any service when the world does not wait); or in
    lockstep with it (a ``participant``). The ``world`` (the simulator) numbers its
    messages and holds those it receives until its step: its own inbox."""
    if kind != "sim":
        return WallClock(), None
    inbox = Inbox(key_intersects) if lockstep != "observer" else None
    if lockstep == "participant" and manifest is not None and inbox is not None:
        ack = bus.publisher(keys.SIM_ACK.at(service=bus.participant))  # before numbering starts

        def acked(t: int, roll_call: bool, published: dict[str, int]) -> None:
            msg = ClockAck(
                stamp_ns=t,
                service=bus.participant,
                sim_ns=t,
                published=published,
                roll_call=roll_call,
                sender=bus.sender,
            )
            with contextlib.suppress(zenoh.ZError):  # the service stopped mid-step
                ack.put(msg)

        step_clock = LockstepClock(
            inbox, acked, manifest.lockstep_deadline_s, bus.counts, bus.begin
        )
        bus.use_lockstep(inbox, step_clock)
        bus.report("lockstep_late", lambda: step_clock.late)
        bus.subscribe(keys.SIM_CLOCK, step_clock.update, immediate=True)
        return step_clock, inbox
    if inbox is not None:
        bus.use_lockstep(inbox)
    sim_clock = SimClock()
    bus.report("clock_refused", lambda: sim_clock.refused)
    bus.subscribe(keys.SIM_CLOCK, sim_clock.update, immediate=True)
    return sim_clock, inbox
