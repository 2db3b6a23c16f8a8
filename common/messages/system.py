"""Messages every service publishes about itself."""

from __future__ import annotations

from common.messages.core import Message, NonNegative


class Health(Message, frozen=True, kw_only=True):
    """Published once a second by every service on ``health/<service>``.

    ``decode_errors`` counts messages (and requests) that failed to decode and were
    dropped since start; ``last_error`` is the latest such failure, one line.
    """

    service: str
    machine: str
    pid: int
    uptime_s: NonNegative
    decode_errors: int = 0
    last_error: str = ""


class Ping(Message, frozen=True, kw_only=True):
    """A no-op request every service answers on ``rpc/<service>/ping`` (round-trip checks)."""

    text: str = ""


class Pong(Message, frozen=True, kw_only=True):
    service: str
    text: str = ""
