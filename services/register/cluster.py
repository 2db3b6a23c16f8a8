"""The scan pairs' alignments on a Dask cluster (:mod:`common.cluster`).

``phenorover register RUN_DIR --cluster tcp://HOST:8786`` (or ``--workers N``, a local
cluster) sends each pair's GICP alignment to a worker as a pure task keyed by the two
scan files, their navigation offset and the options. The task loads its own data: it
reads the two scans from their files and downsamples them (once per scan and worker
process), as the Dask maintainers advise over scattering large arrays; so the run's
scans must be at the same path on every worker (a shared file system). One thread per
task gives the same bits in any process (:mod:`common.workers`), and the results are
gathered in the pairs' order: the registration is the local run's.
"""

from __future__ import annotations

import functools
import logging
from pathlib import Path

from common.cluster import Cluster, file_stamp
from common.pointcloud import read_e57
from common.poses import F64
from services.register.config import RefineConfig
from services.register.graph import PairResult
from services.register.refine import Prepared, align_pair, prepare

log = logging.getLogger(__name__)


class DaskPairs:
    """Aligns the pairs of the scans at ``paths`` on ``cluster`` (:data:`.refine.PairsBy`)."""

    def __init__(self, paths: list[Path], cfg: RefineConfig, cluster: Cluster) -> None:
        self.paths = [str(Path(p).resolve()) for p in paths]
        self.cfg, self.cluster = cfg, cluster

    def __call__(self, todo: list[tuple[int, int, F64]]) -> list[PairResult]:
        stamps = [file_stamp(p) for p in self.paths]
        jobs = [(stamps[i], stamps[j], i, j, rel, self.cfg) for i, j, rel in todo]
        out: list[PairResult] = self.cluster.map(_align, jobs)
        return out


Stamp = tuple[tuple[str, int, int], ...]


def _align(a: Stamp, b: Stamp, i: int, j: int, rel: F64, cfg: RefineConfig) -> PairResult:
    """On a worker: scan ``b`` aligned to scan ``a`` (each its file's stamp)."""
    return align_pair(i, j, _prepared(a, cfg), _prepared(b, cfg), rel, cfg)


@functools.lru_cache(maxsize=16)
def _prepared(stamp: Stamp, cfg: RefineConfig) -> Prepared:
    """A scan read from its file and downsampled, once per worker process and version
    of the file."""
    path = stamp[0][0]
    first = read_e57(path)
    if not first:
        raise ValueError(f"{path}: E57 file holds no scan")
    return prepare(first[0].points, cfg)
