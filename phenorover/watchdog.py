"""Which of the launcher's services hang: alive as processes, silent on the bus.

A service that dies is seen by its exit; one whose whole process stops (SIGSTOP, a
machine swapping to death) keeps its process and, for as long as Zenoh's
lease lets it (10 s), its liveliness token too, so nothing on the bus would say so.
Every service publishes a heartbeat once a second from its own thread
(``health/<service>``, :mod:`common.service`); the launcher hears them on its router
and takes a service whose heartbeat has been silent for ``hung_after_s`` for hung, as
systemd's ``WatchdogSec`` does. The heartbeat's own thread beats on through a deadlock
of the service's main loop: that is caught by its peers, which judge every feed by
the age of what it last said (docs/faults.md). A service is judged only once it has been heard: its
start-up (numba compiles, a snapshot loaded) is not a hang.
"""

from __future__ import annotations

import threading

import msgspec

from common import codec
from common.messages.system import Health


class HeartbeatWatch:
    """Heartbeats of ``machine``'s services by process id, on the caller's monotonic
    clock (seconds); other machines' heartbeats (their pids are theirs) are ignored."""

    def __init__(self, machine: str, hung_after_s: float) -> None:
        self.machine, self.hung_after_s = machine, hung_after_s
        self._heard: dict[int, float] = {}
        self._lock = threading.Lock()

    def heard(self, pid: int, now: float) -> None:
        with self._lock:
            self._heard[pid] = now

    def on_sample(self, payload: bytes, now: float) -> None:
        """A ``health/*`` sample's payload; one that does not decode is no heartbeat."""
        try:
            h: Health = codec.decode(payload, Health)
        except (msgspec.DecodeError, msgspec.ValidationError):
            return
        if h.machine == self.machine:
            self.heard(h.pid, now)

    def silent_for(self, pid: int, now: float) -> float | None:
        """How long ``pid`` has been silent once that is ``hung_after_s`` or more; None
        while it is not (or was never heard)."""
        with self._lock:
            last = self._heard.get(pid)
        if last is None or now - last < self.hung_after_s:
            return None
        return now - last

    def forget(self, pid: int) -> None:
        """A process that exited: its pid may be reused by a new one."""
        with self._lock:
            self._heard.pop(pid, None)
