"""The visibility's chunks of candidates on a Dask cluster (:mod:`common.cluster`).

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

from common.cluster import Cluster
from common.messages.plan import PlanRequest
from services.planner.caster import Cast, Caster, cast_chunk

log = logging.getLogger(__name__)


class DaskChunks:
    """Casts the chunks of ``req``'s visibility on ``cluster``: ``(ranges, options)
    ->`` every chunk's pairs in order (:data:`.visibility.Chunks`)."""

    def __init__(self, req: PlanRequest, cluster: Cluster) -> None:
        self.cluster = cluster
        self._req = msgspec.msgpack.encode(req)

    def __call__(
        self, ranges: list[tuple[int, int]], options: tuple[Any, ...]
    ) -> Iterator[tuple[int, Cast]]:
        """``(end, (pairs, rays))`` of each range in order, ``options`` the
        :class:`.caster.Caster`'s after the field and scanner."""
        jobs = [(self._req, s, e, options) for s, e in ranges]
        for (_, e), cast in zip(ranges, self.cluster.imap(_chunk, jobs), strict=True):
            yield e, cast


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
