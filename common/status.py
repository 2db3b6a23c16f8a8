"""Who is alive on the network: liveliness tokens, read back as a table."""

from __future__ import annotations

import dataclasses
import time

import zenoh

from common import keys


@dataclasses.dataclass(frozen=True)
class Alive:
    machine: str
    service: str
    pid: int
    since_ns: int


def parse_token(key: str) -> Alive | None:
    """``phenorover/alive/<machine>/<service>/<pid>/<since_ns>`` -> Alive, else None."""
    parts = key.split("/")
    prefix = keys.ALIVE_ALL.split("/")[:-1]
    if len(parts) != len(prefix) + 4 or parts[: len(prefix)] != prefix:
        return None
    machine, service, pid, since = parts[len(prefix) :]
    try:
        return Alive(machine, service, int(pid), int(since))
    except ValueError:
        return None


def query_alive(session: zenoh.Session, timeout: float = 2.0) -> list[Alive]:
    found = []
    for reply in session.liveliness().get(keys.ALIVE_ALL, timeout=timeout):
        if reply.ok is not None:
            a = parse_token(str(reply.ok.key_expr))
            if a is not None:
                found.append(a)
    return sorted(found, key=lambda a: (a.machine, a.service, a.pid))


def format_table(entries: list[Alive], now_ns: int | None = None) -> str:
    now_ns = time.time_ns() if now_ns is None else now_ns
    rows = [("SERVICE", "MACHINE", "PID", "SINCE", "UP")]
    for a in entries:
        since = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(a.since_ns / 1e9))
        up = max(0.0, (now_ns - a.since_ns) / 1e9)
        rows.append((a.service, a.machine, str(a.pid), since, f"{up:.1f} s"))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in rows)
