"""Worker processes (the pairwise alignments, the heritability fits): the same results
in the same order as one process, a job's error or a worker's death raised to the
caller, and no worker left running after the call, also when SIGTERM interrupts it."""

from __future__ import annotations

import math
import multiprocessing
import os
import select
import selectors
import signal
import subprocess
import sys
import threading
import time
from typing import IO

import pytest

from common.workers import Worker, WorkerError, starmap
from tests.conftest import REPO


def _say_and_block(seconds: float) -> None:
    """A job that says it runs (its worker's pid, on stdout), then blocks until it is
    ended (or ``seconds`` pass)."""
    # one write: print() writes the number and the newline apart, and two workers
    # sharing the pipe could interleave them ("123456\n", "\n")
    sys.stdout.write(f"{os.getpid()}\n")
    sys.stdout.flush()
    threading.Event().wait(seconds)


def _lines(stream: IO[str], n: int, timeout: float = 30.0) -> list[str]:
    """The next ``n`` lines of ``stream``, each waited for until ``timeout`` s have
    passed in all."""
    end = time.monotonic() + timeout
    out: list[str] = []
    with selectors.DefaultSelector() as sel:
        sel.register(stream, selectors.EVENT_READ)
        while len(out) < n:
            assert sel.select(max(end - time.monotonic(), 0.0)), f"{len(out)} of {n} lines"
            out.append(stream.readline())
    return out


def test_jobs_run_in_other_processes_and_come_back_in_order() -> None:
    jobs = [(float(k), 1.0) for k in range(7)]
    assert starmap(math.hypot, jobs, 2) == [math.hypot(*j) for j in jobs]
    pids = starmap(os.getpid, [()] * 4, 2)
    assert os.getpid() not in pids
    assert not multiprocessing.active_children()  # the workers ended with the call


def test_one_worker_or_one_job_runs_here() -> None:
    assert starmap(os.getpid, [()] * 3, 1) == [os.getpid()] * 3
    assert starmap(os.getpid, [()], 4) == [os.getpid()]
    assert starmap(os.getpid, [], 4) == []


def test_a_jobs_error_reaches_the_caller() -> None:
    with pytest.raises(ValueError, match="math domain error"):
        starmap(math.sqrt, [(4.0,), (-1.0,), (9.0,)], 2)
    assert not multiprocessing.active_children()


def test_a_dead_worker_is_an_error_not_a_hang() -> None:
    with pytest.raises(WorkerError, match="exit code 3"):
        starmap(os._exit, [(3,), (3,), (3,)], 2)
    assert not multiprocessing.active_children()


def test_sigterm_ends_the_workers_at_once() -> None:
    code = (
        "import signal, sys\n"
        "from common.workers import starmap\n"
        "from tests.common.test_workers import _say_and_block\n"
        "signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))\n"  # as the CLI does
        "if __name__ == '__main__':\n"
        "    starmap(_say_and_block, [(60.0,), (60.0,)], 2)\n"
    )
    child = subprocess.Popen(
        [sys.executable, "-c", code], cwd=REPO, stdout=subprocess.PIPE, text=True
    )
    try:
        assert child.stdout is not None
        pids = [int(line) for line in _lines(child.stdout, 2)]
        # a pidfd turns readable when its process ends (and never names another one)
        fds = [os.pidfd_open(p) for p in pids]
        child.send_signal(signal.SIGTERM)
        assert child.wait(timeout=10) == 143
    finally:
        child.kill()
        child.wait()
    end = time.monotonic() + 5
    while fds:
        ready, _, _ = select.select(fds, [], [], max(end - time.monotonic(), 0.0))
        assert ready, f"{len(fds)} workers still running 5 s after the SIGTERM"
        for fd in ready:
            os.close(fd)
        fds = [fd for fd in fds if fd not in ready]


def _pid_and_env(name: str) -> tuple[int, str | None]:
    return os.getpid(), os.environ.get(name)


def _set_env() -> None:
    os.environ["PHENOROVER_TEST_WORKER"] = "initialised"


def test_a_worker_serves_jobs_in_order_beside_its_parent() -> None:
    with Worker(_pid_and_env, _set_env, "test-worker") as w:
        for _ in range(3):
            w.submit("PHENOROVER_TEST_WORKER")
        got = [w.result() for _ in range(3)]
    pid = got[0][0]
    assert pid != os.getpid()
    # one process, its initializer run before the first job
    assert got == [(pid, "initialised")] * 3
    assert not multiprocessing.active_children()


def test_a_workers_error_and_death_reach_the_caller() -> None:
    with Worker(math.sqrt) as w:
        w.submit(-1.0)
        w.submit(4.0)
        with pytest.raises(ValueError, match="math domain error"):
            w.result()
        assert w.result() == 2.0
        with pytest.raises(RuntimeError, match="no job"):
            w.result()
    with Worker(os._exit, name="dying") as w:
        w.submit(3)
        with pytest.raises(WorkerError, match=r"dying \d+ ended \(exit code 3\)"):
            w.result()
    assert not multiprocessing.active_children()


def test_an_exception_ends_the_worker_at_once() -> None:
    with pytest.raises(KeyboardInterrupt), Worker(_say_and_block) as w:
        w.submit(60.0)
        raise KeyboardInterrupt
    assert not multiprocessing.active_children()
