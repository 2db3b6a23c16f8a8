"""Worker processes for the planner service that survive the threads asking for them.

Why not a bare ``ProcessPoolExecutor``: its workers are started lazily by whichever
thread calls ``submit`` (with the ``spawn`` start method), and the planner's workers
ask the kernel for SIGTERM when their parent dies (``PR_SET_PDEATHSIG``, so a killed
service leaves no orphans). Linux sends that signal when the *thread* that started the
child exits, not the process: a worker started from the warm-up thread, or from one of
Zenoh's callback threads, was killed as soon as that thread ended, and the next request
failed with ``BrokenProcessPool``. Here one long-lived dispatcher thread owns the
executor and does every ``submit``, so workers live as long as the pool (and die with
it, or with the service).

A worker can still die (killed for memory, a crash in compiled code). The pool is then
recreated and the request retried once; a second death is reported to the caller as
:class:`WorkerDied`.
"""

from __future__ import annotations

import functools
import logging
import multiprocessing
import queue
import threading
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Generic, TypeVar

from common.process import die_with_parent
from services.planner.budget import limit_memory

log = logging.getLogger(__name__)
T = TypeVar("T")


class WorkerDied(RuntimeError):
    """A planning worker process died while computing (twice, with the retry)."""


def _init_worker(memory_mb: int) -> None:
    die_with_parent()
    limit_memory(memory_mb)


class _Job(Generic[T]):
    def __init__(self, fn: Callable[..., T], args: tuple[Any, ...], retries: int) -> None:
        self.fn, self.args, self.retries = fn, args, retries
        self.out: Future[T] = Future()
        self.generation = -1
        self.started = False  # its future is RUNNING (a retry keeps it so)


class WorkerPool:
    """``workers`` processes (spawned, never forked: the service runs Zenoh's threads)
    running ``submit``-ted functions, each limited to ``memory_mb`` of data (0: no
    limit). ``submit`` never blocks; the returned future holds the result, the
    function's exception, or :class:`WorkerDied`."""

    def __init__(self, workers: int, memory_mb: int = 0, retries: int = 1) -> None:
        self.workers, self.memory_mb, self.retries = workers, memory_mb, retries
        self._jobs: queue.SimpleQueue[_Job[Any] | None] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._generation = 0  # pools made so far; bumped when one breaks
        self._broken = -1  # newest generation seen broken
        self.restarts = 0
        self._pool: ProcessPoolExecutor | None = None
        self._thread = threading.Thread(target=self._dispatch, name="planner-pool", daemon=True)
        self._thread.start()

    def submit(self, fn: Callable[..., T], *args: Any) -> Future[T]:
        job: _Job[T] = _Job(fn, args, self.retries)
        self._jobs.put(job)
        return job.out

    def close(self) -> None:
        """Stop the dispatcher; running workers get SIGTERM as it exits (their parent
        thread is gone), queued jobs are cancelled."""
        self._jobs.put(None)
        self._thread.join(timeout=5.0)

    # --- the dispatcher thread: the only one that creates pools and processes ---
    def _new_pool(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(
            self.workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_init_worker,
            initargs=(self.memory_mb,),
        )

    def _current(self) -> ProcessPoolExecutor:
        with self._lock:
            stale = self._pool is None or self._broken >= self._generation
            if stale:
                old, self._generation = self._pool, self._generation + 1
                if old is not None:
                    self.restarts += 1
                    log.warning("planner worker pool broken: starting a new one")
        if stale:
            if old is not None:
                old.shutdown(wait=False, cancel_futures=True)
            self._pool = self._new_pool()
        assert self._pool is not None
        return self._pool

    def _dispatch(self) -> None:
        while True:
            job = self._jobs.get()
            if job is None:
                break
            if not job.started:
                if not job.out.set_running_or_notify_cancel():
                    continue  # cancelled while queued
                job.started = True
            pool = self._current()
            job.generation = self._generation
            try:
                fut = pool.submit(job.fn, *job.args)
            except BrokenProcessPool:
                self._mark_broken(job.generation)
                self._retry_or_fail(job, "the worker pool was broken")
                continue
            fut.add_done_callback(functools.partial(self._finished, job))
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
        while True:  # whatever was queued behind the stop
            try:
                rest = self._jobs.get_nowait()
            except queue.Empty:
                break
            if rest is not None and not rest.out.cancel():
                rest.out.set_exception(WorkerDied("the planner is stopping"))

    def _mark_broken(self, generation: int) -> None:
        with self._lock:
            self._broken = max(self._broken, generation)

    def _retry_or_fail(self, job: _Job[Any], why: str) -> None:
        if job.retries > 0:
            job.retries -= 1
            self._jobs.put(job)  # its future stays RUNNING until the retry ends
        else:
            job.out.set_exception(WorkerDied(f"planner worker died: {why}"))

    def _finished(self, job: _Job[Any], fut: Future[Any]) -> None:
        exc = fut.exception()
        if isinstance(exc, BrokenProcessPool):
            self._mark_broken(job.generation)
            self._retry_or_fail(job, str(exc) or "killed")
        elif exc is not None:
            job.out.set_exception(exc)
        else:
            job.out.set_result(fut.result())
