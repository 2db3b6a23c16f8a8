"""A command's way onto the network: a client session to its machine's router, one
line when there is none, and waiting for services' liveliness tokens."""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import zenoh

from common.config import ConfigError, load_manifest, zenoh_config
from common.status import Alive, query_alive

REPO = Path(__file__).resolve().parent.parent
DEFAULT_MANIFEST = REPO / "deploy" / "sim.toml"


# how long a command waits for its machine's router: it is local, so it is either
# there or not (a router just started by `phenorover up` is listening within this)
CONNECT_TIMEOUT_S = 3.0


class Unreachable(ConnectionError):
    """No router answered at the endpoints; the message names them, on one line."""


def add_connection_arguments(p: argparse.ArgumentParser) -> None:
    """``--manifest`` and ``--connect``: where a command finds its machine's router
    (:func:`client_endpoints`)."""
    p.add_argument(
        "--manifest", type=Path, default=None, help="deploy manifest (default: deploy/sim.toml)"
    )
    p.add_argument(
        "--connect", action="append", default=[], metavar="ENDPOINT", help="router endpoint"
    )


def client_endpoints(manifest: Path | None, connect: list[str]) -> list[str]:
    """``--connect`` if given, else where the manifest's machine reaches its router."""
    if connect:
        return connect
    return load_manifest(manifest or DEFAULT_MANIFEST).zenoh.local_endpoints()


def open_client(
    manifest: Path | None, connect: list[str], timeout_s: float = CONNECT_TIMEOUT_S
) -> zenoh.Session:
    """A client session to a machine's router: the CLI's way onto the network.

    Raises Unreachable when no router accepts within ``timeout_s`` (a Zenoh client
    opens only once it has a router: an open session always has one) and ConfigError
    for a bad manifest."""
    connect = client_endpoints(manifest, connect)
    zenoh.init_log_from_env_or("error")
    try:
        return zenoh.open(zenoh_config("client", [], connect, client_timeout_s=timeout_s))
    except zenoh.ZError:
        where = ", ".join(connect)
        raise Unreachable(
            f"no router at {where} within {timeout_s:g} s (is `phenorover up` running "
            "on this machine?)"
        ) from None


def connect_or_explain(
    prog: str, manifest: Path | None, connect: list[str], service: str | None = None
) -> zenoh.Session | None:
    """open_client for a command: None after printing one line to stderr when the
    deployment cannot be reached, the manifest is wrong, or (with ``service``) no such
    service is alive behind the router, e.g. the robot is off or its link down (the
    caller exits 2). Without that check a call would wait for its full timeout."""
    try:
        session = open_client(manifest, connect)
    except (Unreachable, ConfigError) as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return None
    if service is None or any(a.service == service for a in query_alive(session, 2.0)):
        return session
    session.close()
    where = ", ".join(client_endpoints(manifest, connect))
    print(
        f"{prog}: no {service} service alive behind {where} (the router is up: is the "
        f"machine running {service} on and linked?)",
        file=sys.stderr,
    )
    return None


@dataclasses.dataclass(frozen=True)
class AliveWait:
    """What :func:`wait_alive` found: true only when every wanted service was seen,
    so ``assert wait_alive(...)`` fails when one is missing."""

    seen: list[Alive]
    missing: frozenset[str]

    def __bool__(self) -> bool:
        return not self.missing


def wait_alive(
    session: zenoh.Session, services: set[str], timeout: float, machine: str | None = None
) -> AliveWait:
    """Poll liveliness until every name in ``services`` is alive (on ``machine``, when
    given) or ``timeout`` passes."""
    deadline = time.monotonic() + timeout
    while True:
        seen = query_alive(session, timeout=1.0)
        names = {a.service for a in seen if machine is None or a.machine == machine}
        missing = frozenset(services - names)
        if not missing or time.monotonic() >= deadline:
            return AliveWait(seen, missing)
        time.sleep(0.2)  # a poll period, not a synchronisation: liveliness is re-queried
