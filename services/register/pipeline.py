"""``register``: navigation placement, C2C refinement, the target-based reference and
all metrics for the scans of one survey. Progress goes to logging.

It takes what a real robot has (the scans and their navigation poses) and nothing
else: every metric is against the target-based reference. Scoring against the
simulator's truth is the evaluation's (``phenorover/eval/register``), from the outputs:
the report keeps each scan's file, its poses of every method and its spheres."""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from common.pointcloud import PosedScan, read_e57
from common.poses import F64, check_pose
from services.register.config import RegisterConfig
from services.register.graph import TargetObservation, optimise_graph
from services.register.metrics import (
    cloud_distance,
    merged,
    overlap_stats,
    point_stats,
    subsample,
    target_stats,
)
from services.register.outcome import (
    MethodReport,
    PairReport,
    Pose,
    Registration,
    RegistrationReport,
    ScanReport,
)
from services.register.refine import (
    PairsBy,
    Prepared,
    prepare,
    prior_sigmas,
    refine,
    select_pairs,
)
from services.register.spheres import SphereDetection, detect_spheres
from services.register.targets import (
    TargetSolution,
    match_targets,
    solve_targets,
)

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True, eq=False)
class ScanInput:
    """One scan: an E57 file with its points in the scanner frame (its first data3D
    entry is read, its pose ignored) and the navigation pose (4x4 field <- scanner,
    see :func:`common.poses.scanner_pose`)."""

    path: Path
    nav_pose: F64
    name: str = ""


def _as_list(m: F64) -> Pose:
    return [[float(v) for v in row] for row in m]


def register(
    scans: list[ScanInput], cfg: RegisterConfig | None = None, pairs_by: PairsBy | None = None
) -> Registration:
    """Register ``scans`` (see the module docstring): read them, place them by
    navigation and find their spheres, refine (C2C), solve the target-based reference,
    then score every method against it. Raises ValueError (naming the file) for an
    unreadable scan or a bad pose. ``pairs_by``: where the pairs are aligned
    (:mod:`.cluster`; default: here)."""
    cfg = cfg or RegisterConfig()
    if not scans:
        raise ValueError("register: no scans given")
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    rng = np.random.default_rng(cfg.seed)
    placed = _place(scans, cfg, rng, timings)

    t = time.perf_counter()
    obs = [
        TargetObservation(i, int(lab), placed.centres[i][m])
        for i in range(len(placed.data))
        for m, lab in enumerate(placed.labels[i])
        if lab >= 0
    ]
    c2c, pairs = refine(placed.prepared, placed.nav, cfg.refine, obs, pairs_by)
    timings["c2c"] = time.perf_counter() - t

    t = time.perf_counter()
    tsol = solve_targets(placed.centres, placed.nav, cfg.targets)
    timings["targets"] = time.perf_counter() - t
    total = time.perf_counter() - t0
    log.info("registration took %.1f s", total)

    t = time.perf_counter()
    # what the clouds alone give (the paper's C2C), for comparison: the pose graph
    # again without the spheres
    plain = (
        optimise_graph(placed.nav, pairs, prior_sigmas(cfg.refine))
        if cfg.refine.use_targets and obs
        else c2c
    )
    score = _scorer(placed, tsol, cfg, rng)
    nav_r, c2c_r, tgt_r = score(placed.nav, False), score(c2c, False), score(tsol.poses, True)
    plain_r = score(plain, False) if plain is not c2c else None
    timings["metrics"] = time.perf_counter() - t
    report = RegistrationReport(
        scans=_scan_reports(scans, placed, c2c, tsol, None if plain_r is None else plain),
        pairs=[
            PairReport(
                i=p.i,
                j=p.j,
                overlap=p.overlap,
                rmse=p.rmse if math.isfinite(p.rmse) else -1.0,
                kept=p.kept,
                reason=p.reason,
            )
            for p in pairs
        ],
        navigation=nav_r,
        c2c=c2c_r,
        target_based=tgt_r,
        c2c_without_targets=plain_r,
        timings=timings,
        time_s=total,
    )
    out_scans = [dataclasses.replace(d, pose=p) for d, p in zip(placed.data, c2c, strict=True)]
    return Registration(
        report,
        placed.nav,
        c2c,
        tsol.poses,
        out_scans,
        placed.centres,
        [np.asarray(lab, dtype=np.int64) for lab in placed.labels],
        None if plain_r is None else plain,
    )


@dataclasses.dataclass(frozen=True, eq=False)
class _Placed:
    """The scans read (``data``) at their navigation poses (``nav``), downsampled for
    the refinement (``prepared``), with the spheres found in each (``found``, their
    ``centres`` in the scanner frame and the target each is matched to, ``labels``)."""

    nav: list[F64]
    data: list[PosedScan]
    prepared: list[Prepared]
    found: list[list[SphereDetection]]
    centres: list[F64]
    labels: list[npt.NDArray[np.int64]]


def _place(
    scans: list[ScanInput], cfg: RegisterConfig, rng: np.random.Generator,
    timings: dict[str, float],
) -> _Placed:  # fmt: skip
    t = time.perf_counter()
    nav = [check_pose(s.nav_pose, f"{s.path}: navigation pose") for s in scans]
    data: list[PosedScan] = []
    for s, p in zip(scans, nav, strict=True):
        first = read_e57(s.path)
        if not first:
            raise ValueError(f"{s.path}: E57 file holds no scan")
        name = s.name or Path(s.path).stem
        data.append(PosedScan(first[0].points, first[0].intensity, p, name))
    timings["read"] = time.perf_counter() - t
    log.info("read %d scans (%d points)", len(data), sum(len(d.points) for d in data))

    t = time.perf_counter()
    prepared = [prepare(d.points, cfg.refine) for d in data]
    timings["downsample"] = time.perf_counter() - t

    t = time.perf_counter()
    found = [detect_spheres(d.points, d.intensity, cfg.spheres, rng) for d in data]
    centres = [np.array([f.fit.centre for f in fs]).reshape(-1, 3) for fs in found]
    labels = match_targets(centres, nav, cfg.targets.match_radius)
    timings["spheres"] = time.perf_counter() - t  # found in each scan, and matched
    log.info("spheres per scan: %s", [len(f) for f in found])
    return _Placed(nav, data, prepared, found, centres, labels)


def _scorer(
    placed: _Placed, tsol: TargetSolution, cfg: RegisterConfig, rng: np.random.Generator
) -> Callable[[list[F64], bool], MethodReport]:
    """Scores a method's poses against the target-based reference: the targets, and
    unless it is the reference itself its scan points and cloud; and its overlap
    residuals over the pairs navigation put near each other (the same for every
    method)."""
    data = placed.data
    samples = [subsample(d.points, cfg.sample_points, rng) for d in data]
    # the full-resolution reference cloud, cropped like the C2C input
    rmax = cfg.refine.max_range
    full = [d.points[np.linalg.norm(d.points, axis=1) <= rmax] for d in data]
    ref_cloud = merged(full, tsol.poses)
    ref_tree = cKDTree(ref_cloud)  # once for every method scored against it
    clouds = [(pr.points, pr.normals, cKDTree(pr.points)) for pr in placed.prepared]
    near = select_pairs(placed.nav, cfg.refine.max_pair_distance)
    cropped = [s[np.linalg.norm(s, axis=1) <= rmax] for s in samples]

    def score(poses: list[F64], is_reference: bool) -> MethodReport:
        pts, cloud = None, None
        if not is_reference:
            pts = point_stats(samples, poses, tsol.poses)
            src = subsample(merged(samples, poses), cfg.cloud_points, rng)
            cloud = cloud_distance(src, ref_cloud, ref_tree)
        return MethodReport(
            targets_vs_reference=target_stats(placed.centres, placed.labels, poses, tsol.centres),
            points_vs_reference=pts,
            cloud_vs_reference=cloud,
            overlap=overlap_stats(clouds, cropped, poses, near, cfg.overlap_radius),
        )

    return score


def _scan_reports(
    scans: list[ScanInput], placed: _Placed, c2c: list[F64], tsol: TargetSolution,
    plain: list[F64] | None,
) -> list[ScanReport]:  # fmt: skip
    return [
        ScanReport(
            name=d.name,
            points=len(d.points),
            downsampled=len(pr.points),
            spheres=len(fs),
            sphere_rms=[f.fit.rms for f in fs],
            targets=tsol.n_targets[k],
            target_solved=tsol.solved[k],
            nav_pose=_as_list(placed.nav[k]),
            c2c_pose=_as_list(c2c[k]),
            target_pose=_as_list(tsol.poses[k]),
            file=str(scans[k].path),
            sphere_centres=[(float(c[0]), float(c[1]), float(c[2])) for c in placed.centres[k]],
            sphere_targets=[int(v) for v in placed.labels[k]],
            c2c_without_targets_pose=None if plain is None else _as_list(plain[k]),
        )
        for k, (d, pr, fs) in enumerate(
            zip(placed.data, placed.prepared, placed.found, strict=True)
        )
    ]
