"""The simulator's side of lockstep (:mod:`common.lockstep`): whom each step waits
for, and what it expects delivered.

A participant is waited for from its first acknowledgement until its liveliness
token (``sim/lockstep/<service>``) goes: so one that is still starting, or whose
first tick Zenoh had no route for yet, holds no step up, and one that dies holds up
none after it. A tick nobody acknowledged within half a second is sent again (a
participant that saw it acknowledges it again); one still missing after the
manifest's ``lockstep_deadline_s`` is logged and the world steps on without it.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from common import keys
from common.messages.sim import ClockAck
from common.transport import Bus

log = logging.getLogger(__name__)
RESEND_S = 0.5


class Barrier:
    def __init__(self, bus: Bus, deadline_s: float) -> None:
        self.deadline_s = deadline_s
        self._cond = threading.Condition()
        self._acked: dict[str, int] = {}  # participant -> the step time it last acked
        # participant -> the name its messages go by, and how many it has published
        self._counts: dict[str, tuple[str, dict[str, int]]] = {}
        self._alive: set[str] = set()
        self.late = 0  # steps taken without a participant's acknowledgement
        bus.subscribe(keys.SIM_ACK.at(service="*"), self._on_ack, immediate=True)
        bus.watch(keys.LOCKSTEP_ALL, self._on_token)

    def _on_ack(self, ack: ClockAck) -> None:
        # a roll call's answer counts as a step just before the one it was called at
        at = ack.sim_ns - 1 if ack.roll_call else ack.sim_ns
        with self._cond:
            if at >= self._acked.get(ack.service, at - 1):
                self._acked[ack.service] = at
                self._counts[ack.service] = (ack.sender or ack.service, dict(ack.published))
            self._cond.notify_all()

    def _on_token(self, key: str, alive: bool) -> None:
        name = key.rsplit("/", 1)[-1]
        with self._cond:
            if alive:
                self._alive.add(name)
            else:  # gone: waited for no more, until it acknowledges again
                self._alive.discard(name)
                self._acked.pop(name, None)
            self._cond.notify_all()

    def expect(self, own: str, counts: dict[str, int]) -> dict[str, int]:
        """What the next step expects delivered: every participant's messages as of
        its last acknowledgement, and ``own``'s ``counts`` (the simulator's)."""
        with self._cond:
            out = {f"{who}|{k}": n for who, c in self._counts.values() for k, n in c.items()}
        return out | {f"{own}|{k}": n for k, n in counts.items()}

    def participants(self) -> list[str]:
        with self._cond:
            return sorted(self._alive & set(self._acked))

    def wait(
        self,
        t_ns: int,
        resend: Callable[[], None],
        stop: threading.Event,
        everyone: bool = False,
    ) -> list[str]:
        """Until every participant has acknowledged the step at ``t_ns`` (sending its
        tick again every ``RESEND_S``): those that never did within the deadline.
        ``everyone``: a service whose token is up counts even before its first
        acknowledgement (the roll call before the world's first step)."""
        end = time.monotonic() + self.deadline_s
        next_send = time.monotonic() + RESEND_S
        unheard = t_ns - 1 if everyone else t_ns
        with self._cond:
            while True:
                late = [s for s in self._alive if self._acked.get(s, unheard) < t_ns]
                now = time.monotonic()
                if not late or stop.is_set():
                    return []
                if now > end:
                    break
                if now > next_send:
                    next_send = now + RESEND_S
                    self._cond.release()
                    try:
                        resend()
                    finally:
                        self._cond.acquire()
                self._cond.wait(min(end, next_send) - now)
        self.late += 1
        log.warning(
            "lockstep: %s did not acknowledge sim time %.2f s within %g s: stepping on",
            ", ".join(sorted(late)),
            t_ns / 1e9,
            self.deadline_s,
        )
        return sorted(late)
