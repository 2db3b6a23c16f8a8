"""What the conformance suites share: services (and device simulators) run in threads
of the test process, each on a Zenoh client session of its own, as their processes
would run them.

Each suite (``test_gnss.py``, ``test_scanner.py``, ``test_base.py``) is one contract
per device kind, run against every backend of that kind by a parametrized fixture (as
python-can runs one interface suite against every bus): the test plays the simulator
on ``client_bus``; the backend under test and its far end each get their own session.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Protocol

import pytest

from common.clock import WallClock
from common.service import Context
from common.transport import Bus
from tests.conftest import client, router


class Runs(Protocol):
    def run(self, stop: threading.Event) -> None: ...


@pytest.fixture(scope="package")
def router_endpoint() -> Iterator[str]:
    """One Zenoh router for the suites (opening one takes half a second); every test
    still opens sessions of its own and closes them."""
    with router() as ep:
        yield ep


def context(bus: Bus, name: str, run_dir: Path) -> Context:
    """What the runner gives service ``name`` on ``bus`` (wall clock, the ENGR field)."""
    return Context(name, "test", bus, WallClock(), logging.getLogger(name), run_dir, "engr")


class Running:
    """Runs services in threads (``start``) and stops them (``close``, or the end of a
    ``with`` block) last started first, so that a far end (a device simulator) goes
    after the service that talks to it; fails when one does not stop within 5 s. Enter
    it after the sessions the services use, so that it stops them before those close."""

    def __init__(self) -> None:
        self._threads: list[tuple[threading.Thread, threading.Event]] = []

    def start(self, service: Runs, name: str) -> None:
        stop = threading.Event()
        thread = threading.Thread(target=service.run, args=(stop,), name=name)
        thread.start()
        self._threads.append((thread, stop))

    def close(self) -> None:
        for thread, stop in reversed(self._threads):
            stop.set()
            thread.join(timeout=5.0)
            assert not thread.is_alive(), f"{thread.name} did not stop within 5 s"

    def __enter__(self) -> Running:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@contextlib.contextmanager
def sessions(
    endpoint: str, *names: str
) -> Iterator[tuple[list[Bus], contextlib.ExitStack, Running]]:
    """A client session of the router at ``endpoint`` per name (a service's, its far
    end's), a :class:`Running` that stops the services before those close, and an exit
    stack for whatever else is opened on the way (closed first)."""
    with contextlib.ExitStack() as stack:
        buses = [stack.enter_context(client(endpoint, n)) for n in names]
        run = stack.enter_context(Running())
        yield buses, stack, run
