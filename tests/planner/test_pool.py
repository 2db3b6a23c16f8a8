"""The planner's worker pool: workers outlive the thread that first asked for them
(the BrokenProcessPool of issue 11), a dead worker is replaced and its job retried
once, and a worker's memory is limited."""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from services.planner.pool import WorkerDied, WorkerPool


def pid() -> int:
    return os.getpid()


def die_once(marker: str) -> int:
    """Kill this worker the first time (as the kernel's OOM killer would), then work."""
    if not os.path.exists(marker):
        Path(marker).touch()
        os.kill(os.getpid(), signal.SIGKILL)
    return os.getpid()


def die() -> int:
    os.kill(os.getpid(), signal.SIGKILL)
    return 0


def allocate(mb: int) -> int:
    return int(np.ones(mb << 17).sum())  # float64: 8 bytes each


@pytest.fixture
def pool() -> Iterator[WorkerPool]:
    p = WorkerPool(1, memory_mb=1024)
    yield p
    p.close()


def test_workers_outlive_the_thread_that_started_them(pool: WorkerPool) -> None:
    first: list[int] = []
    # the warm-up thread's way: submit from a thread that then ends
    th = threading.Thread(target=lambda: first.append(pool.submit(pid).result(timeout=60)))
    th.start()
    th.join()
    assert first
    # PR_SET_PDEATHSIG fires on the exit of the parent *thread*: before the fix the
    # worker got SIGTERM here and this raised BrokenProcessPool
    assert pool.submit(pid).result(timeout=60) == first[0]
    assert pool.restarts == 0


def test_a_dead_worker_is_replaced_and_its_job_retried_once(
    pool: WorkerPool, tmp_path: Path
) -> None:
    before = pool.submit(pid).result(timeout=60)
    after = pool.submit(die_once, str(tmp_path / "died")).result(timeout=60)
    assert after != before and pool.restarts == 1
    with pytest.raises(WorkerDied, match="planner worker died"):
        pool.submit(die).result(timeout=60)
    assert pool.submit(pid).result(timeout=60) > 0  # and it keeps serving


def test_a_worker_beyond_its_memory_limit_gets_memory_error(pool: WorkerPool) -> None:
    with pytest.raises(MemoryError):
        pool.submit(allocate, 2048).result(timeout=60)
    assert pool.submit(allocate, 16).result(timeout=60) == 16 << 17
    assert pool.restarts == 0
