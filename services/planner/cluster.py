"""The visibility's chunks of candidates on a Dask cluster (``dask.distributed``).

``phenorover plan --cluster tcp://HOST:8786`` sends them to a running scheduler and
its workers, on this machine or others; ``--workers N`` starts a local cluster of N
single-threaded worker processes for the one plan. Each chunk is a pure task keyed
by the request and its candidates: it gets the request (the field given inline, as
layout parameters or GeoJSON text: a few kilobytes), builds the field itself (once
per worker process) and casts its candidates, as the Dask maintainers advise over
scattering large arrays. The results are gathered in the candidates' order, so the
table, and the plan, are the local run's, byte for byte. A worker lost mid-plan has
its chunks run again on another, to the same result.

A regular field's table is one candidate's, moved to the others
(:mod:`.lattice`): nothing is sent to the cluster for it.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Iterator
from typing import Any

import msgspec

from common.messages.plan import PlanRequest
from services.planner.visibility import Cast, Caster, cast_chunk

log = logging.getLogger(__name__)


class ClusterError(RuntimeError):
    """The cluster cannot be reached or started; one line naming it."""


class DaskChunks:
    """Runs the chunks of a plan's visibility on a Dask cluster: ``(ranges, options)
    ->`` every chunk's pairs in order (:data:`.visibility.Chunks`). ``address``: a
    scheduler's, waited for ``timeout_s``; else a local cluster of ``workers``
    processes. A context manager: leaving it closes the client (and a local cluster
    it started)."""

    def __init__(
        self,
        req: PlanRequest,
        address: str | None = None,
        workers: int = 0,
        timeout_s: float = 10.0,
    ) -> None:
        from distributed import Client, LocalCluster

        # the scheduler's and client's INFO lines (connections opened and closed) say
        # nothing a planner's user acts on; warnings and errors still show
        logging.getLogger("distributed").setLevel(logging.WARNING)
        self._cluster: Any = None
        self._req = msgspec.msgpack.encode(req)
        self._key = _request_key(self._req)
        try:
            if address:
                self.client = Client(address, timeout=f"{timeout_s}s")
                self.where = address
            else:
                self._cluster = LocalCluster(
                    n_workers=max(1, workers),
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                    silence_logs=logging.WARNING,
                )
                self.client = Client(self._cluster)
                self.where = f"a local cluster of {max(1, workers)} worker processes"
        except (OSError, TimeoutError) as exc:
            self.close()
            raise ClusterError(f"cannot reach the Dask scheduler at {address}: {exc}") from None

    def __call__(
        self, ranges: list[tuple[int, int]], options: tuple[Any, ...]
    ) -> Iterator[tuple[int, Cast]]:
        """``(end, pairs)`` of each range in order, ``options`` those of
        :func:`.visibility.cast_chunk` after the request and the range."""
        from distributed import as_completed

        futures = [
            self.client.submit(
                _chunk, self._req, s, e, options, key=f"visibility-{self._key}-{s}-{e}", pure=True
            )
            for s, e in ranges
        ]
        log.info("visibility: %d chunks sent to %s", len(futures), self.where)
        done: dict[int, Any] = {}
        order = {f.key: k for k, f in enumerate(futures)}
        nxt = 0
        for fut in as_completed(futures):
            done[order[fut.key]] = fut.result()
            fut.release()
            while nxt in done:
                yield ranges[nxt][1], done.pop(nxt)
                nxt += 1

    def close(self) -> None:
        client = getattr(self, "client", None)
        if client is not None:
            client.close()
        if self._cluster is not None:
            self._cluster.close()

    def __enter__(self) -> DaskChunks:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


def _request_key(raw: bytes) -> str:
    import hashlib

    return hashlib.sha256(raw).hexdigest()[:16]


def _chunk(req: bytes, s: int, e: int, options: tuple[Any, ...]) -> Cast:
    """On a worker: the pairs of candidates s..e of the request's field, and the rays
    cast for them."""
    return cast_chunk(_caster(req, options), s, e)


@functools.lru_cache(maxsize=2)
def _caster(req: bytes, options: tuple[Any, ...]) -> Caster:
    """The request's field and caster, built once per worker process."""
    from services.planner.request import resolve_field

    r = msgspec.msgpack.decode(req, type=PlanRequest)
    _, field = resolve_field(r)
    return Caster(field, r.scanner, *options)
