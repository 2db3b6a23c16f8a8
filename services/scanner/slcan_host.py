"""python-can's ``slcan`` bus, plus what the adapter says about the CAN bus.

python-can 4.6's slcan interface reads only frames: it ignores the adapter's BELL
(a refused command or transmit) and never asks for the status flags, so a bus whose
other node is gone looks merely quiet, and ``state`` is always ACTIVE. A Lawicel
adapter reports that trouble only when asked (``F``), so :class:`SlcanHost` asks
every ``status_poll_s`` while it is being read, and from the flags:

- ``state`` is ``BusState.ERROR`` on a bus error, ``PASSIVE`` on error passive,
  else ``ACTIVE``;
- :meth:`SlcanHost.send` raises ``can.CanOperationError`` while the state is ERROR,
  as python-can's socketcan does when frames find no node to acknowledge them
  (ENOBUFS), so callers see bus-off the same way on every interface;
- ``refused`` counts the commands and transmits the adapter answered with BELL.

An adapter that does not know ``F`` answers BELL to the poll; that is harmless, the
state then stays ACTIVE.
"""

from __future__ import annotations

import contextlib
import time
from typing import Any

import can
from can.interfaces.slcan import slcanBus

_FLAG_NAMES = (
    (0x80, "bus error"),
    (0x20, "error passive"),
    (0x04, "error warning"),
    (0x02, "transmit FIFO full"),
    (0x01, "receive FIFO full"),
    (0x08, "data overrun"),
)
BUS_ERROR, ERROR_PASSIVE = 0x80, 0x20


def describe_flags(flags: int) -> str:
    """``0xA6`` -> 'bus error, error passive, error warning, transmit FIFO full
    (adapter status flags 0xA6)'."""
    names = ", ".join(name for bit, name in _FLAG_NAMES if flags & bit) or "no error"
    return f"{names} (adapter status flags 0x{flags:02X})"


class SlcanHost(slcanBus):
    """See the module docstring; arguments as python-can's ``slcan`` interface.
    Like it, not thread-safe: one thread reads and sends."""

    def __init__(self, channel: str, *, status_poll_s: float = 0.5, **kwargs: Any) -> None:
        # set before python-can's constructor, which already talks to the adapter
        self.flags = 0
        self.refused = 0
        self._poll_s = status_poll_s
        self._next_poll = 0.0
        super().__init__(channel, **kwargs)

    @property
    def state(self) -> can.BusState:
        if self.flags & BUS_ERROR:
            return can.BusState.ERROR
        return can.BusState.PASSIVE if self.flags & ERROR_PASSIVE else can.BusState.ACTIVE

    @state.setter
    def state(self, new_state: can.BusState) -> None:
        raise NotImplementedError("SLCAN has no command to set the bus state")

    def error(self) -> str:
        """What is wrong with the bus in one line; empty while it is ACTIVE."""
        return "" if self.state == can.BusState.ACTIVE else describe_flags(self.flags)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self.state == can.BusState.ERROR:
            raise can.CanOperationError(f"Failed to transmit: {describe_flags(self.flags)}")
        super().send(msg, timeout)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        now = time.monotonic()
        if now >= self._next_poll:
            self._next_poll = now + self._poll_s
            self._write("F")
        if self._queue.qsize():  # lines python-can put aside while awaiting V or N
            return super()._recv_internal(0.0)
        deadline = None if timeout is None else now + timeout
        while True:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            line = self._read(left)
            if line is None:
                return None, False
            if not self._adapter_reply(line):
                self._queue.put_nowait(line)  # a frame: python-can's own parser takes it
                return super()._recv_internal(0.0)
            if deadline is not None and time.monotonic() >= deadline:
                return None, False

    def _adapter_reply(self, line: str) -> bool:
        """Take the adapter's answers to commands (the frames are not ours)."""
        if line.startswith("F") and len(line) >= 3:
            # not hex: not a status reply, and the flags keep their last value
            with contextlib.suppress(ValueError):
                self.flags = int(line[1:3], 16)
            return True
        if line == "\a":
            self.refused += 1
            return True
        return line in ("\r", "z\r", "Z\r")
