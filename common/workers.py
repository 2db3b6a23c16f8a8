"""Jobs in worker processes: :func:`starmap` runs independent jobs (the registration's
pairwise alignments) on several cores, each job whole in one single-threaded worker;
:class:`Worker` is one process a program hands jobs to and goes on with its own work
(the traits' heritability fits while it draws and writes).

Why processes and not threads: small_gicp holds the GIL while it aligns, so Python
threads run its calls one after the other. Why not its OpenMP threads: they meet at a
barrier several times every GICP iteration, and at ``nice 10`` on two cores shared
with a running simulation (the registration at the end of ``phenorover sim``) each
barrier waits for whichever core was taken away: on the 11-scan ENGR survey under
load the pairs took 94 s of wall time and 31 s of CPU with two OpenMP threads, 22 s
and 20 s with one. A job in its own process meets nobody until it is done, and a job
run in one thread gives the same bits in any process, so the worker count changes how
long a registration takes, never what it finds.

Why not ``multiprocessing.Pool`` or ``ProcessPoolExecutor``: a Pool replaces a worker
that dies (one that cannot import the main module dies at every start) and waits
forever for its job; an executor interrupted by SIGTERM finishes its queued jobs
before the process may exit, long after the mission service's 2 s grace. Here every
worker has its own pipe and the parent alone hands out jobs: a dead worker is an
error, and an interrupted call terminates its workers at once. A parent killed
outright (SIGKILL) cannot: its workers end when they next talk to it, after the job
at hand (seconds).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import signal
from collections.abc import Callable, Iterator, Sequence
from multiprocessing.connection import Connection, wait
from multiprocessing.process import BaseProcess
from typing import Any, TypeVar

T = TypeVar("T")


class WorkerError(RuntimeError):
    """A worker process ended while it held a job (killed, out of memory, or unable to
    start: a program calling :func:`starmap` without the ``__main__`` guard)."""


def starmap(fn: Callable[..., T], jobs: Sequence[tuple[Any, ...]], workers: int) -> list[T]:
    """``[fn(*job) for job in jobs]``, run on up to ``workers`` processes (in this one
    when one worker or one job is all there is). ``fn`` must be a module-level function
    and the jobs and results picklable; a program calling this needs the ``if
    __name__ == "__main__"`` guard (a worker imports the main module). A job's
    exception is raised here, a worker's death as :class:`WorkerError`; the workers
    have ended when the call returns or raises (SIGTERM's SystemExit included)."""
    n = min(workers, len(jobs))
    if n <= 1:
        return [fn(*job) for job in jobs]
    # spawn, not fork: a fork copies no thread but every lock a thread held (zenoh's,
    # libgomp's pool after the scans' downsampling), so a forked child can hang
    ctx = multiprocessing.get_context("spawn")
    procs: list[BaseProcess] = []
    conns: list[Connection] = []
    ok = False
    try:
        for _ in range(n):
            here, there = ctx.Pipe()
            p = ctx.Process(target=_serve, args=(fn, there), daemon=True, name="worker")
            p.start()
            there.close()  # so the worker's death reads as EOF here
            procs.append(p)
            conns.append(here)
        out = _run(iter(enumerate(jobs)), conns, procs)
        ok = True
        return [out[k] for k in range(len(jobs))]
    finally:
        _end(conns, procs, ok)


def _run(
    todo: Iterator[tuple[int, tuple[Any, ...]]], conns: list[Connection], procs: list[BaseProcess]
) -> dict[int, Any]:
    """Each job to the next idle worker; the results by job index."""
    busy: dict[Connection, int] = {}
    out: dict[int, Any] = {}

    def feed(c: Connection) -> None:
        job = next(todo, None)
        if job is None:
            return
        try:
            c.send(job)
        except OSError:
            raise _died(procs[conns.index(c)], job[0]) from None
        busy[c] = job[0]

    for c in conns:
        feed(c)
    while busy:
        for ready in wait(list(busy)):
            assert isinstance(ready, Connection)
            try:
                k, done, value = ready.recv()
            except EOFError:
                raise _died(procs[conns.index(ready)], busy[ready]) from None
            del busy[ready]
            if not done:
                raise value
            out[k] = value
            feed(ready)
    return out


def _died(p: BaseProcess, job: int) -> WorkerError:
    p.join(timeout=5)
    return WorkerError(f"{p.name} {p.pid} ended (exit code {p.exitcode}) in job {job}")


class Worker:
    """One spawned process serving ``fn`` while its parent goes on: ``submit`` queues a
    job, ``result`` waits for the oldest one's result (its exception raised here, the
    worker's death as :class:`WorkerError`). ``initializer`` runs in the worker as it
    starts, before any job: slow imports done while the parent works. A context
    manager: leaving it ends the worker, at once when an exception (SIGTERM's
    SystemExit included) leaves it. The same needs as :func:`starmap`'s."""

    def __init__(
        self,
        fn: Callable[..., Any],
        initializer: Callable[[], object] | None = None,
        name: str = "worker",
    ) -> None:
        ctx = multiprocessing.get_context("spawn")  # not fork: see starmap
        here, there = ctx.Pipe()
        self._proc = ctx.Process(
            target=_serve, args=(fn, there, initializer), daemon=True, name=name
        )
        self._proc.start()
        there.close()
        self._conn = here
        self._sent = self._got = 0

    def submit(self, *args: Any) -> None:
        try:
            self._conn.send((self._sent, args))
        except OSError:
            raise _died(self._proc, self._sent) from None
        self._sent += 1

    def result(self) -> Any:
        if self._got == self._sent:
            raise RuntimeError("no job submitted to wait for")
        try:
            _, done, value = self._conn.recv()
        except EOFError:
            raise _died(self._proc, self._got) from None
        self._got += 1
        if not done:
            raise value
        return value

    def close(self, ok: bool = True) -> None:
        """End the worker: after its jobs when ``ok``, else at once."""
        _end([self._conn], [self._proc], ok)

    def __enter__(self) -> Worker:
        return self

    def __exit__(self, kind: type[BaseException] | None, *_: object) -> None:
        self.close(ok=kind is None)


def _end(conns: list[Connection], procs: list[BaseProcess], ok: bool) -> None:
    for c in conns:
        if ok:
            with contextlib.suppress(OSError):
                c.send(None)
        c.close()
    for p in procs:
        if ok:
            p.join(timeout=5)
        if p.is_alive():
            p.terminate()
        p.join()


def _serve(
    fn: Callable[..., Any], conn: Connection, initializer: Callable[[], object] | None = None
) -> None:
    """A worker: jobs from ``conn`` until None or the parent is gone."""
    # Ctrl-C reaches the whole process group: the parent's handling ends the workers
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if initializer is not None:
        initializer()
    while True:
        try:
            msg = conn.recv()
        except EOFError:
            return
        if msg is None:
            return
        k, args = msg
        try:
            reply = (k, True, fn(*args))
        except Exception as exc:
            reply = (k, False, exc)
        try:
            conn.send(reply)
        except OSError:  # the parent is gone
            return
        except Exception as exc:  # a result or an exception that does not pickle
            conn.send((k, False, WorkerError(f"job {k}: {reply[2]!r} not sent back: {exc}")))
