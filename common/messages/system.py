"""Messages every service publishes about itself."""

from __future__ import annotations

import msgspec

from common.messages.core import Message, NonNegative


class ConfigQuery(Message, frozen=True, kw_only=True):
    """Ask a service for the configuration it runs with (``rpc/<service>/config``)."""


class ServiceConfig(Message, frozen=True, kw_only=True):
    """A service's configuration as it resolved it (its manifest section, ``--set``
    overrides and the defaults of everything not given), as TOML: what
    ``--dump-config`` prints."""

    service: str
    machine: str
    toml: str


class Health(Message, frozen=True, kw_only=True):
    """Published once a second by every service on ``health/<service>``.

    ``decode_errors`` counts messages (and requests) that failed to decode and were
    dropped since start; ``last_error`` is the latest such failure, one line.
    ``callback_errors`` counts messages that decoded but whose subscriber callback
    raised, and requests whose handler raised anything but a RequestError (answered
    as internal errors): each is a bug or input the service could not take, and the
    service lives on, so this count is where it shows. ``counters``: the service's
    own counts of input it refused or recovered from (``Bus.report``), by name.
    """

    service: str
    machine: str
    pid: int
    uptime_s: NonNegative
    decode_errors: int = 0
    last_error: str = ""
    callback_errors: int = 0
    counters: dict[str, int] = msgspec.field(default_factory=dict)


class Ping(Message, frozen=True, kw_only=True):
    """A no-op request every service answers on ``rpc/<service>/ping`` (round-trip checks)."""

    text: str = ""


class Pong(Message, frozen=True, kw_only=True):
    service: str
    text: str = ""
