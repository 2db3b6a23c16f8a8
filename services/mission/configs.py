"""The configuration a mission ran with, saved in its run folder (``config.toml``).

A manifest as written says little on its own: defaults fill what it leaves out, and
``--set`` overrides change what it says. So at a mission's start every service of
the robot is asked, over Zenoh, for the configuration it resolved
(``rpc/<service>/config``, answered by :mod:`common.service`), and the answers are
written as one TOML document: ``[services.<name>]`` tables as a manifest has them,
and ``[machines]`` saying where each service ran. A resumed mission whose services
answer otherwise keeps the first record and adds ``config.resumed-<k>.toml``, said in
the mission log.
"""

from __future__ import annotations

import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgspec

from common import keys
from common.files import write_atomic
from common.messages.system import ConfigQuery, ServiceConfig
from common.transport import Bus

CONFIG_FILE = "config.toml"
# how long (wall) the services may take to answer: each answers at once, from memory
GATHER_S = 2.0
HEADER = (
    "# The configuration each service of this robot ran the mission with, as it\n"
    "# resolved it (manifest, --set overrides, defaults); gathered at the mission's start.\n"
)


def save_configs(bus: Bus, folder: Path, say: Callable[[str, str], None]) -> Path:
    """Ask every service of the robot for its configuration and :func:`record` the
    answers in ``folder``. Called as a mission is launched, before its worker runs:
    there (a command's handler, or the service's start) the world in lockstep waits
    for the mission, so the wall time the answers take changes nothing in the run,
    where the worker, once driving, would start its first route at another sim time."""
    return record(folder, gather(bus, GATHER_S), say)


def gather(bus: Bus, timeout_s: float) -> list[ServiceConfig]:
    """Every service's answer within ``timeout_s`` (wall seconds), by name."""
    got = bus.gather(keys.CONFIG.at(service="*"), ConfigQuery(), timeout_s)
    return sorted({c.service: c for c in got}.values(), key=lambda c: c.service)


def document(configs: list[ServiceConfig]) -> dict[str, Any]:
    """The TOML document of ``configs``; a section that is not TOML is kept as text,
    under ``[unreadable]``, rather than lost."""
    doc: dict[str, Any] = {"machines": {}, "services": {}}
    for c in configs:
        doc["machines"][c.service] = c.machine
        try:
            doc["services"][c.service] = tomllib.loads(c.toml)
        except tomllib.TOMLDecodeError:
            doc.setdefault("unreadable", {})[c.service] = c.toml
    return doc


def record(folder: Path, configs: list[ServiceConfig], say: Callable[[str, str], None]) -> Path:
    """Write ``configs`` to ``folder``'s ``config.toml``, or, when that holds another
    record (a resumed mission whose services changed), beside it; the path written
    (or the one already holding the same)."""
    text = HEADER + msgspec.toml.encode(document(configs)).decode()
    path = folder / CONFIG_FILE
    k = 1
    while path.exists():
        if path.read_text() == text:
            return path
        path = folder / f"config.resumed-{k}.toml"
        k += 1
    write_atomic(path, text.encode(), durable=True)
    names = ", ".join(c.service for c in configs) or "none answered"
    if path.name == CONFIG_FILE:
        say("info", f"configuration recorded in {path.name} ({names})")
    else:
        say("warning", f"the services' configuration differs from the mission's start: {path.name}")
    return path
