"""What a router's access control refused, from Zenoh's own log: the policy is
:mod:`common.acl`; this reads its verdicts (``phenorover up`` turns them into one
warning per kind of denial, :class:`DenialLog`)."""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable

from common.process import strip_ansi

# Zenoh's access control logs through this target: one trace line per message checked
LOG_TARGET = "zenoh::net::routing::interceptor::access_control"
_VERDICT = re.compile(
    r"(?P<zid>[0-9a-f]+) on (?P<subject>\S+) is (?P<verdict>un)?authorized to "
    r"(?P<action>.+?) \((?P<flow>ingress|egress)\) on (?P<key>\S+)"
)
_STRANGER = re.compile(r"(?P<zid>[0-9a-f]+) did not match any configured ACL subject")
_CN = re.compile(r"CertCommonName\(([^)]*)\)")


@dataclasses.dataclass(frozen=True)
class Denial:
    """What the router refused: who sent it (certificate common name, else the link),
    what it was (``Put``, ``Query``, ...; ``anything`` for a link no subject matches),
    the flow and the key."""

    who: str
    action: str
    flow: str = "ingress"
    key: str = "**"

    def __str__(self) -> str:
        return f"denied: {self.who} may not {self.action} ({self.flow}) on {self.key}"


def parse_denial(line: str) -> Denial | None:
    """The denial a line of Zenoh's access-control log reports, if it reports one."""
    line = strip_ansi(line)
    m = _VERDICT.search(line)
    if m is not None:
        if not m["verdict"]:
            return None
        cn = _CN.search(m["subject"])
        who = cn[1] if cn else m["subject"].rsplit("+", 1)[0]
        return Denial(who, m["action"], m["flow"], m["key"])
    m = _STRANGER.search(line)
    return Denial(f"unknown link {m['zid']}", "anything") if m else None


class DenialLog:
    """Turns Zenoh's access-control log (a trace line per message checked, allowed or
    not) into one warning per kind of denial: the first at once, then a count at most
    every ``every_s`` while it goes on, so a machine flooding a denied key cannot flood
    the log. ``feed`` returns whether the line was the access control's (consumed)."""

    def __init__(self, emit: Callable[[str], None], every_s: float = 10.0) -> None:
        self.emit, self.every_s = emit, every_s
        self._last: dict[Denial, float] = {}
        self._since: dict[Denial, int] = {}

    def feed(self, line: str, now: float) -> bool:
        if LOG_TARGET not in line:
            return False
        d = parse_denial(line)
        if d is None:
            return True
        last = self._last.get(d)
        if last is None or now - last >= self.every_s:
            more = self._since.pop(d, 0)
            self.emit(f"{d}" + (f" ({more} more since)" if more else ""))
            self._last[d] = now
        else:
            self._since[d] = self._since.get(d, 0) + 1
        return True
