"""The heritability fits (:mod:`.stats`) in a second process, beside the rest of a run.

statsmodels takes about a second to import and each trait's REML fit a fifth of one,
all Python under one interpreter lock. A worker started as soon as a run's field book
is read imports statsmodels while the cloud is cut and the ground found, and fits the
traits while this process draws the field map and writes the files: on two cores
the fits leave the command's wall time. Should the worker die, the fits are made here.
"""

from __future__ import annotations

import collections
import logging

from common.workers import Worker, WorkerError
from services.traits import breeding
from services.traits.compute import TraitTable
from services.traits.stats import Heritability, import_statsmodels

log = logging.getLogger("phenorover.traits")


class Fits:
    """Submit a run's trait table, take its heritabilities later, in order."""

    def __init__(self) -> None:
        self._worker = Worker(breeding.heritabilities, import_statsmodels, "traits-fits")
        self._tables: collections.deque[TraitTable] = collections.deque()
        self._alive = True

    def submit(self, table: TraitTable) -> None:
        self._tables.append(table)
        if self._alive:
            try:
                self._worker.submit(table)
            except WorkerError as exc:
                self._lost(exc)

    def next(self) -> dict[str, Heritability]:
        """The heritabilities of the oldest table submitted."""
        table = self._tables.popleft()
        if self._alive:
            try:
                out: dict[str, Heritability] = self._worker.result()
                return out
            except WorkerError as exc:
                self._lost(exc)
        return breeding.heritabilities(table)

    def _lost(self, exc: WorkerError) -> None:
        log.warning("%s: the heritabilities are fitted in this process", exc)
        self._alive = False

    def __enter__(self) -> Fits:
        return self

    def __exit__(self, kind: type[BaseException] | None, *_: object) -> None:
        self._worker.close(ok=kind is None)
