"""The pairwise alignments' worker processes: the same results in the same order as
one process, a job's error or a worker's death raised to the caller, and no worker
left running after the call, also when SIGTERM interrupts it."""

from __future__ import annotations

import math
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from services.register.workers import WorkerError, starmap

REPO = Path(__file__).resolve().parents[2]


def _mark_and_sleep(path: str, seconds: float) -> None:
    """A job that says it runs (its worker's pid in ``path``), then takes its time."""
    tmp = f"{path}.tmp"
    Path(tmp).write_text(str(os.getpid()))
    os.replace(tmp, path)
    time.sleep(seconds)


def _wait_for(cond: Callable[[], bool], timeout: float = 30.0) -> None:
    end = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.05)


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


def test_sigterm_ends_the_workers_at_once(tmp_path: Path) -> None:
    marks = [tmp_path / f"job{k}" for k in range(2)]
    code = (
        "import signal, sys\n"
        "from services.register.workers import starmap\n"
        "from tests.register.test_workers import _mark_and_sleep\n"
        "signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))\n"  # as the CLI does
        "if __name__ == '__main__':\n"
        f"    starmap(_mark_and_sleep, [(p, 60.0) for p in {[str(m) for m in marks]!r}], 2)\n"
    )
    child = subprocess.Popen([sys.executable, "-c", code], cwd=REPO)
    try:
        _wait_for(lambda: all(m.exists() for m in marks))
        pids = [int(m.read_text()) for m in marks]
        child.send_signal(signal.SIGTERM)
        assert child.wait(timeout=10) == 143
    finally:
        child.kill()
        child.wait()

    def gone(pid: int) -> bool:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        return False

    _wait_for(lambda: all(gone(p) for p in pids), timeout=5)
