"""Shared fixtures: free loopback ports, a Zenoh router in the test process, a client
bus, and process management that fails a test which leaves a process behind."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any, TypeVar

import pytest
import zenoh
from hypothesis import settings

from common.config import zenoh_config
from common.keys import Topic
from common.messages.plan import PlanResult
from common.process import free_loopback_port
from common.transport import Bus

REPO = Path(__file__).resolve().parent.parent
M = TypeVar("M")
os.environ.setdefault("RERUN_ANALYTICS", "0")

# CI replays the same examples every run (a submission must not pass or fail by luck);
# developers keep hypothesis' random search, which is what finds new edge cases.
settings.register_profile("ci", derandomize=True, deadline=None)
if os.environ.get("CI"):
    settings.load_profile("ci")


def free_port() -> int:
    return free_loopback_port()


@contextlib.contextmanager
def router() -> Iterator[str]:
    """A Zenoh router on a free loopback port, hosted by the test process: its
    endpoint."""
    ep = f"tcp/127.0.0.1:{free_port()}"
    with zenoh.open(zenoh_config("router", [ep], [])):
        yield ep


@pytest.fixture
def router_endpoint() -> Iterator[str]:
    """A Zenoh router for the test (:func:`router`)."""
    with router() as ep:
        yield ep


@contextlib.contextmanager
def client(endpoint: str, name: str = "test", namespace: str = "") -> Iterator[Bus]:
    """A bus on a client session of the router at ``endpoint`` (a robot's with
    ``namespace``), closed on exit."""
    session = zenoh.open(zenoh_config("client", [], [endpoint]))
    bus = Bus(session, name, namespace=namespace)
    try:
        yield bus
    finally:
        bus.close()
        session.close()


@pytest.fixture
def client_bus(router_endpoint: str) -> Iterator[Bus]:
    with client(router_endpoint) as bus:
        yield bus


class Procs:
    """Starts processes and guarantees they are gone after the test."""

    def __init__(self) -> None:
        self.procs: list[subprocess.Popen[bytes]] = []

    def start(
        self, *args: str, log: Path | None = None, wrap: Sequence[str] = ()
    ) -> subprocess.Popen[bytes]:
        """``python args`` from the repository; ``wrap``: a command that execs it (``ip
        netns exec NS``), so that the process is still the one that was started."""
        out = open(log, "wb") if log is not None else subprocess.DEVNULL  # noqa: SIM115
        env = dict(os.environ, PYTHONUNBUFFERED="1", PHENOROVER_LOG="info")
        p = subprocess.Popen(
            [*wrap, sys.executable, *args], cwd=REPO, stdout=out, stderr=subprocess.STDOUT, env=env
        )
        self.procs.append(p)
        return p

    def service(
        self, module_or_path: str, endpoint: str, *extra: str, log: Path | None = None
    ) -> subprocess.Popen[bytes]:
        target = ["-m", module_or_path] if not module_or_path.endswith(".py") else [module_or_path]
        return self.start(*target, "--connect", endpoint, "--machine", "test", *extra, log=log)

    def stop_all(self) -> list[int]:
        leaked = []
        for p in self.procs:
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + 5.0
        for p in self.procs:
            try:
                p.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                leaked.append(p.pid)
                p.kill()
                p.wait()
        return leaked


@pytest.fixture
def procs() -> Iterator[Procs]:
    ps = Procs()
    yield ps
    leaked = ps.stop_all()
    assert not leaked, f"processes did not stop on SIGTERM within 5 s: {leaked}"


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie is dead for our purposes
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split()[2] != "Z"
    except FileNotFoundError:
        return False


class Record(list[M]):
    """Every message on a topic as it arrives, and waits on what has arrived."""

    def __init__(self) -> None:
        super().__init__()
        self.cond = threading.Condition()

    def add(self, m: M) -> None:
        with self.cond:
            self.append(m)
            self.cond.notify_all()

    def until(self, done: Callable[[list[M]], bool], timeout: float) -> bool:
        """Whether ``done(messages so far)`` came true within ``timeout`` seconds."""
        with self.cond:
            return self.cond.wait_for(lambda: done(self), timeout)

    def wait_for(self, pred: Callable[[M], bool], timeout: float) -> M | None:
        """The newest message satisfying ``pred``, waiting up to ``timeout`` for one."""
        self.until(lambda ms: any(pred(m) for m in ms[-50:]), timeout)
        with self.cond:
            return next((m for m in reversed(self) if pred(m)), None)


def record(bus: Bus, topic: Topic[M]) -> Record[M]:
    out: Record[M] = Record()
    bus.subscribe(topic, out.add)
    return out


@pytest.fixture(scope="session")
def engr_split() -> PlanResult:
    """ENGR's plan split between two robots (each robot's share: ``share_of``)."""
    from common.battery import Pace
    from common.field import load_field
    from common.messages.plan import PlanOptions
    from services.planner.core import plan

    layout, fld = load_field("engr")
    opt = PlanOptions(robots=2, tour_time_limit_s=1.0, pace=Pace(speed=0.5, location_s=300.0))
    return plan(layout, field=fld, options=opt)


class FakeBus:
    """A bus that keeps each subscription's and liveliness watch's callback, by key;
    nothing is sent (a test calls them as the bus would)."""

    def __init__(self) -> None:
        self.subs: dict[str, Callable[[Any], object]] = {}
        self.watched: dict[str, Callable[[str, bool], object]] = {}
        self.namespace = ""

    def subscribe(self, topic: Any, callback: Callable[[Any], object]) -> None:
        self.subs[topic.key] = callback

    def watch(self, key: str, callback: Callable[[str, bool], object]) -> None:
        self.watched[key] = callback
