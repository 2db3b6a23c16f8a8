"""Faults the FARO emulator can be told to have (``[services.scanner.sim_faults]``),
each aimed at every scan or at the scan ids listed."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Annotated

import msgspec

from common.messages.core import NonNegative

log = logging.getLogger(__name__)


class FaroFaults(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Faults to inject (the scanner's ``[services.scanner.sim_faults]``). Times are on
    the emulator's clock (sim seconds in simulation). Each ``*_scan_ids`` list aims its
    fault at those scan ids (empty: every scan). A command concerns the scan it names
    (Initiate, End) or the current one (Record/Pause)."""

    lose_first_acks: Annotated[int, msgspec.Meta(ge=0)] = 0
    """The first N commands are executed but their ACK is lost (with ``lose_scan_ids``:
    the first N of each listed scan)."""
    lose_first_commands: Annotated[int, msgspec.Meta(ge=0)] = 0
    """The first N commands never reach the device (with ``lose_scan_ids``: the first N
    of each listed scan)."""
    no_ack: bool = False
    """The device ignores every command (a dead command path); status frames still
    flow."""
    error_code: Annotated[int, msgspec.Meta(ge=0, le=65535)] = 0
    """Above 0: the scan fails with this code when it reaches ``error_at_pct``."""
    error_at_pct: NonNegative = 50.0
    """The progress (%) at which ``error_code`` fails the scan."""
    stuck_at_pct: NonNegative | None = None
    """Progress freezes at this (%) and the scan never completes; none: it does not."""
    error_scan_ids: list[int] = msgspec.field(default_factory=list)
    """The scans ``error_code`` fails."""
    stuck_scan_ids: list[int] = msgspec.field(default_factory=list)
    """The scans that get stuck at ``stuck_at_pct``."""
    lose_scan_ids: list[int] = msgspec.field(default_factory=list)
    """The scans whose commands or ACKs are lost (``lose_first_*``)."""
    no_ack_scan_ids: list[int] = msgspec.field(default_factory=list)
    """The scans whose commands the device ignores (``no_ack``)."""
    bus_off_for_s: NonNegative = 0.0
    """Above 0: right after it acknowledges the Initiate of the first aimed scan, the
    scanner's CAN node goes bus-off for this long, once: it sends and hears nothing (the
    scan itself goes on), and the client's sends fail with ``can.CanOperationError``,
    as python-can reports a bus with no one to acknowledge
    (:class:`services.scanner.sim.device.BusOffGate`; across an SLCAN link,
    :mod:`services.scanner.sim.slcan_device` reports it as an adapter does). A scan
    that completes meanwhile reports DONE once the bus is back, but its Inclinometer
    frame is lost."""
    bus_off_scan_ids: list[int] = msgspec.field(default_factory=list)
    """The scans bus-off may come at: the first of them to start; empty: the first
    scan."""


def aimed(ids: list[int], scan_id: int) -> bool:
    return not ids or scan_id in ids


class FaultBook:
    """What the faults have done so far on one emulator: the commands and ACKs lost
    per scan id (or in all, when the losses are aimed at no scan), and the one
    bus-off with its end on the emulator's clock ``now`` (s)."""

    def __init__(self, faults: FaroFaults, now: Callable[[], float]) -> None:
        self.faults = faults
        self._now = now
        self._lost_commands: dict[int | None, int] = {}
        self._lost_acks: dict[int | None, int] = {}
        self._bus_off_used, self._bus_off_until = False, -float("inf")

    def lose_command(self, scan_id: int) -> bool:
        """Is this command, concerning ``scan_id``, lost on its way in?"""
        return self._lose(self._lost_commands, self.faults.lose_first_commands, scan_id)

    def lose_ack(self, scan_id: int) -> bool:
        """Is the ACK of this command, concerning ``scan_id``, lost?"""
        return self._lose(self._lost_acks, self.faults.lose_first_acks, scan_id)

    def _lose(self, counts: dict[int | None, int], first: int, sid: int) -> bool:
        """One more loss of the first ``first`` (per scan with ``lose_scan_ids``)?"""
        ids = self.faults.lose_scan_ids
        key = sid if ids else None
        if not aimed(ids, sid) or counts.get(key, 0) >= first:
            return False
        counts[key] = counts.get(key, 0) + 1
        return True

    def started(self, scan_id: int) -> None:
        """Scan ``scan_id`` was acknowledged: the node goes bus-off now if aimed so."""
        f = self.faults
        if f.bus_off_for_s > 0 and not self._bus_off_used and aimed(f.bus_off_scan_ids, scan_id):
            self._bus_off_used = True
            self._bus_off_until = self._now() + f.bus_off_for_s
            log.warning(
                "FARO emulator: bus-off (fault) for %g s at scan %d", f.bus_off_for_s, scan_id
            )

    def bus_off(self) -> bool:
        """Is the node bus-off now? Any thread."""
        return self._now() < self._bus_off_until
