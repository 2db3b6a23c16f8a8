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
from collections.abc import Callable, Iterator, Sequence
from typing import Any

log = logging.getLogger(__name__)


class ClusterError(RuntimeError):
    """The cluster cannot be reached or started; one line naming it."""


class Cluster:
    """A client of the scheduler at ``address`` (waited for ``timeout_s``), else of a
    local cluster of ``workers`` processes; raises :class:`ClusterError`. A context
    manager: leaving it closes the client, and the local cluster it started."""

    def __init__(self, address: str | None = None, workers: int = 0, timeout_s: float = 10.0):
        from distributed import Client, LocalCluster

        # the scheduler's and client's INFO lines (connections opened and closed) say
        # nothing a user acts on; warnings and errors still show
        logging.getLogger("distributed").setLevel(logging.WARNING)
        self._local: Any = None
        self.client: Any = None
        try:
            if address:
                self.client = Client(address, timeout=f"{timeout_s}s")
                self.where = address
            else:
                n = max(1, workers)
                self._local = LocalCluster(
                    n_workers=n,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                    silence_logs=logging.WARNING,
                )
                self.client = Client(self._local)
                self.where = f"a local cluster of {n} worker processes"
        except (OSError, TimeoutError) as exc:
            self.close()
            where = address or "a local cluster"
            raise ClusterError(f"cannot reach the Dask scheduler at {where}: {exc}") from None

    def in_order(self, futures: Sequence[Any]) -> Iterator[tuple[int, Any]]:
        """(index, result) of ``futures`` in their order, each as soon as it and all
        before it are done; a task's exception is raised here."""
        from distributed import as_completed

        index = {f.key: k for k, f in enumerate(futures)}
        done: dict[int, Any] = {}
        nxt = 0
        for fut in as_completed(futures):
            done[index[fut.key]] = fut.result()
            fut.release()
            while nxt in done:
                yield nxt, done.pop(nxt)
                nxt += 1

    def map(self, fn: Callable[..., Any], jobs: Sequence[tuple[Any, ...]]) -> list[Any]:
        """``[fn(*job) for job in jobs]`` on the cluster, in the jobs' order (``fn``
        importable by the workers; Dask keys each task by its function and
        arguments)."""
        futures = [self.client.submit(fn, *job) for job in jobs]
        return [r for _, r in self.in_order(futures)]

    def close(self) -> None:
        if self.client is not None:
            self.client.close()
        if self._local is not None:
            self._local.close()

    def __enter__(self) -> Cluster:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


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
