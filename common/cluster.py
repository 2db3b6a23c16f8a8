"""A Dask cluster for batch work (``dask.distributed``): a running scheduler's, or a
local cluster of single-threaded worker processes started for one command.

The commands that use one (``phenorover plan``, ``phenorover register``) send pure
tasks keyed by what they compute and gather the results in the order they were
submitted, so the output is the local run's whatever the workers and whichever of
them is lost (Dask runs a lost worker's tasks again on another). docs/scale.md.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)


class ClusterError(RuntimeError):
    """The cluster cannot be reached or started; one line naming it."""


class Cluster:
    """A client of the scheduler at ``address`` (waited for ``timeout_s``, and for a
    worker as long), else of a local cluster of ``workers`` processes; raises
    :class:`ClusterError`. A task's result is waited for ``task_timeout_s`` at most
    (a cluster that lost every worker). A context manager: leaving it closes the
    client, and the local cluster it started."""

    def __init__(
        self,
        address: str | None = None,
        workers: int = 0,
        timeout_s: float = 10.0,
        task_timeout_s: float = 3600.0,
    ) -> None:
        from distributed import Client, LocalCluster

        # the scheduler's and client's INFO lines (connections opened and closed) say
        # nothing a user acts on; warnings and errors still show
        logging.getLogger("distributed").setLevel(logging.WARNING)
        self._local: Any = None
        self.client: Any = None
        self.task_timeout_s = task_timeout_s
        where = address or "a local cluster"
        try:
            if address:
                self.client = Client(address, timeout=f"{timeout_s}s")
                self.where = address
            else:
                n = max(1, workers)
                # on loopback only, its status page on a free port (two commands at
                # once would both want 8787)
                self._local = LocalCluster(
                    n_workers=n,
                    threads_per_worker=1,
                    processes=True,
                    host="127.0.0.1",
                    dashboard_address="127.0.0.1:0",
                    silence_logs=logging.WARNING,
                )
                self.client = Client(self._local)
                self.where = f"a local cluster of {n} worker processes"
            self.client.wait_for_workers(1, timeout=timeout_s)
        except (OSError, TimeoutError) as exc:
            self.close()
            raise ClusterError(f"cannot reach the Dask scheduler at {where}: {exc}") from None

    def imap(self, fn: Callable[..., Any], jobs: Sequence[tuple[Any, ...]]) -> Iterator[Any]:
        """``fn(*job)`` of every job on the cluster, yielded in the jobs' order (``fn``
        importable by the workers; Dask keys each task by its function and
        arguments); a task's exception is raised here."""
        futures = [self.client.submit(fn, *job) for job in jobs]
        log.info("%d tasks of %s sent to %s", len(futures), fn.__name__, self.where)
        try:
            for f in futures:
                try:
                    yield f.result(timeout=self.task_timeout_s)
                except TimeoutError:
                    raise ClusterError(
                        f"{self.where}: no result from a task in {self.task_timeout_s:g} s "
                        "(no worker left?)"
                    ) from None
                f.release()
        finally:
            for f in futures:
                f.release()

    def map(self, fn: Callable[..., Any], jobs: Sequence[tuple[Any, ...]]) -> list[Any]:
        """The results of :meth:`imap`, as a list."""
        return list(self.imap(fn, jobs))

    def everywhere(self, fn: Callable[[], object]) -> None:
        """Run ``fn()`` in every worker process (e.g. to drop what it cached)."""
        self.client.run(fn)

    def close(self) -> None:
        if self.client is not None:
            self.client.close()
        if self._local is not None:
            self._local.close()

    def __enter__(self) -> Cluster:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


def file_stamp(*paths: str | Path) -> tuple[tuple[str, int, int], ...]:
    """Each file's path, size and modification time (0, 0 when missing): what a worker's
    cache of what it read is keyed by, so that a long-running worker never serves a
    file as it was before it changed."""
    out = []
    for p in paths:
        try:
            st = os.stat(p)
            out.append((str(p), st.st_size, st.st_mtime_ns))
        except OSError:
            out.append((str(p), 0, 0))
    return tuple(out)


def add_cluster_arguments(p: argparse.ArgumentParser, what: str) -> None:
    """``--cluster ADDRESS`` and ``--workers N``, for a command that runs ``what`` on
    a Dask cluster."""
    p.add_argument(
        "--cluster",
        default=None,
        metavar="ADDRESS",
        help=f"run {what} on a Dask scheduler's workers (tcp://HOST:8786; docs/scale.md)",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=0,
        metavar="N",
        help=f"run {what} on a local Dask cluster of N worker processes",
    )


def cluster_of(args: argparse.Namespace) -> contextlib.AbstractContextManager[Cluster | None]:
    """The cluster ``--cluster`` or ``--workers`` asks for (None: run here)."""
    if not (args.cluster or args.workers):
        return contextlib.nullcontext()
    return Cluster(args.cluster, args.workers)
