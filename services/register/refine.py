"""Cloud-to-cloud refinement of all scans jointly.

1. Every scan is cropped to ``max_range`` and voxel-downsampled; normals and local
   covariances come from its neighbours (small_gicp).
2. Scans whose navigation positions are within ``max_pair_distance`` are aligned
   pairwise by GICP, starting from the navigation relative pose, with the paper's
   30 cm correspondence radius ("we limited the radius to search for common points
   to 30 cm"), then again at ``fine_correspondence``. Only points that both scanners
   see from similar directions (within ``view_angle_deg``) take part, plus near-
   horizontal ground: a porous canopy is hit on the side facing each scanner, so two
   scans looking at it from opposite sides see surfaces a leaf cluster apart, and
   matching them pulls the scans together (measured in simulation: 1.5-2 cm along
   the baseline of scans 4 m apart, 2 mm with the filter). A pair is kept when
   enough of the source overlaps the target and the correction stays within what
   navigation errors can explain.
3. A pose graph over all scans is solved by nonlinear least squares: each kept pair
   pulls the two scans towards its relative pose with a point-to-plane information
   matrix, and each scan is held to its navigation pose by a prior of what that pose
   is worth (millimetres in xy after standing through a scan, worse in z, the
   compensator's tilt, the compass heading). The priors fix the global placement (the
   graph's gauge), its rotation mostly through the scans' positions: the relative
   poses come from the clouds.
   Registration spheres seen by two or more scans join the graph (``use_targets``):
   their positions are unknowns, and each fitted centre placed by its scan's pose
   is pulled onto its sphere. In the ENGR survey most scans share too little with
   any neighbour for GICP, and a shared sphere ties them where the clouds cannot.

Poses are 4x4 ``field <- scanner``; the correction of scan i is parametrised as in
:func:`.poses.perturb` (field-frame translation and rotation vector).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable

import numpy as np
import small_gicp
from scipy.spatial import cKDTree

from common.poses import F64, apply, inv
from common.workers import starmap
from services.register.config import RefineConfig
from services.register.graph import PairResult, TargetObservation, optimise_graph
from services.register.poses import difference

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True, eq=False)
class Prepared:
    """A downsampled scan (scanner frame): points (M, 3) and unit normals (M, 3)."""

    points: F64
    normals: F64


def prepare(points: F64, cfg: RefineConfig) -> Prepared:
    """Crop to ``max_range``, voxel-downsample and estimate normals of one scan
    (scanner frame). Raises ValueError when fewer than 100 points remain."""
    pts = np.asarray(points, dtype=np.float64)
    pts = pts[np.linalg.norm(pts, axis=1) <= cfg.max_range]
    # one thread: the same points and normals as with more, in one order (with more
    # they come in a different order at every run), and no OpenMP barrier to wait at
    # on a loaded machine (see .workers)
    cloud, _ = small_gicp.preprocess_points(
        pts, downsampling_resolution=cfg.voxel, num_neighbors=cfg.neighbours, num_threads=1
    )
    if cloud.size() < 100:
        raise ValueError(f"scan has {cloud.size()} points after downsampling (need >= 100)")
    p = np.ascontiguousarray(cloud.points()[:, :3])
    return Prepared(p, np.ascontiguousarray(cloud.normals()[:, :3]))


def _common_view(scan: Prepared, other_origin: F64, cfg: RefineConfig) -> Prepared:
    """Points of ``scan`` that a scanner at ``other_origin`` (this scan's frame) sees
    from within ``view_angle_deg`` of this scanner's view, plus ground."""
    q, n = scan.points, scan.normals
    a = q / np.linalg.norm(q, axis=1)[:, None]
    b = q - other_origin
    b /= np.maximum(np.linalg.norm(b, axis=1), 1e-9)[:, None]
    keep = np.einsum("ij,ij->i", a, b) >= math.cos(math.radians(cfg.view_angle_deg))
    keep |= np.abs(n[:, 2]) >= cfg.ground_normal_z
    return Prepared(np.ascontiguousarray(q[keep]), n[keep])


def _with_covariances(
    points: F64, cfg: RefineConfig
) -> tuple[small_gicp.PointCloud, small_gicp.KdTree]:
    """GICP's input: the points with their local covariances, and their k-d tree (one
    thread: a pair is one worker's job, see :func:`refine`)."""
    cloud = small_gicp.PointCloud(points)
    tree = small_gicp.KdTree(cloud, num_threads=1)
    small_gicp.estimate_covariances(cloud, tree, cfg.neighbours, 1)
    return cloud, tree


def pair_information(
    tgt_kd: cKDTree,
    tgt_normals: F64,
    src_in_tgt: F64,
    max_dist: float,
    sigma: float,
    voxel: float = 0.0,
) -> F64:
    """Point-to-plane information (6x6, rotation then translation, target frame) of
    the correspondences between source points already in the target frame and the
    target: sum of J^T J / sigma^2 with J = [p x n, n], scaled by the share of
    distinct ``voxel`` cubes among the points (one independent residual per cube)."""
    d, k = tgt_kd.query(src_in_tgt, distance_upper_bound=max_dist)
    ok = np.isfinite(d)
    p, n = src_in_tgt[ok], tgt_normals[k[ok]]
    jac = np.column_stack([np.cross(p, n), n])
    out: F64 = jac.T @ jac / sigma**2
    if voxel > 0 and len(p):
        n_eff = len(np.unique(np.floor(p / voxel).astype(np.int64), axis=0))
        out *= n_eff / len(p)
    return out


def align_pair(
    i: int, j: int, tgt_scan: Prepared, src_scan: Prepared, init_ij: F64, cfg: RefineConfig
) -> PairResult:
    """GICP of scan j onto scan i from ``init_ij`` (j -> i), coarse then fine, on the
    points both see from similar directions. Single-threaded (see :func:`refine`)."""
    tgt = _common_view(tgt_scan, init_ij[:3, 3], cfg)
    src = _common_view(src_scan, inv(init_ij)[:3, 3], cfg)
    kd = cKDTree(tgt.points)
    # skip GICP where too little overlaps even within the coarse radius at the start:
    # to end with ``min_overlap`` of the points within the fine radius, the rest would
    # have to move by more than the difference of the radii (0.2 m), forty times the
    # navigation prior's sigma and beyond what the gate lets a pair correct
    d0, _ = kd.query(apply(init_ij, src.points), distance_upper_bound=cfg.coarse_correspondence)
    start = float(np.isfinite(d0).mean())
    if start < cfg.min_overlap:
        info = np.zeros((6, 6))
        radius = cfg.coarse_correspondence
        why = f"overlap {start:.2f} < {cfg.min_overlap} within {radius} m at the start"
        return PairResult(i, j, init_ij, info, start, math.inf, False, why)
    tgt_cloud, tgt_tree = _with_covariances(tgt.points, cfg)
    src_cloud, _ = _with_covariances(src.points, cfg)
    t = init_ij
    for dist in (cfg.coarse_correspondence, cfg.fine_correspondence):
        res = small_gicp.align(
            tgt_cloud,
            src_cloud,
            tgt_tree,
            init_T_target_source=t,
            registration_type="GICP",
            max_correspondence_distance=dist,
            num_threads=1,
            max_iterations=cfg.max_iterations,
            rotation_epsilon=cfg.epsilon,
            translation_epsilon=cfg.epsilon,
        )
        t = np.asarray(res.T_target_source, dtype=np.float64)
    moved = apply(t, src.points)
    d, _ = kd.query(moved, distance_upper_bound=cfg.fine_correspondence)
    ok = np.isfinite(d)
    overlap = float(ok.mean())
    rmse = float(np.sqrt(np.mean(d[ok] ** 2))) if ok.any() else math.inf
    reason = ""
    if overlap < cfg.min_overlap:
        reason = f"overlap {overlap:.2f} < {cfg.min_overlap}"
    else:
        # the correction in the field frame (j's origin and rotation) against the
        # relative navigation sigmas
        dxyz, drot = difference(t, init_ij)
        corr = np.concatenate([dxyz, drot]) / (math.sqrt(2) * prior_sigmas(cfg))
        worst = int(np.argmax(np.abs(corr)))
        if abs(corr[worst]) > cfg.gate_sigma:
            names = ("x", "y", "z", "roll", "pitch", "yaw")
            reason = f"{names[worst]} correction is {abs(corr[worst]):.1f} nav sigmas"
    sigma = max(cfg.point_sigma, rmse) if math.isfinite(rmse) else cfg.point_sigma
    info = pair_information(
        kd, tgt.normals, moved, cfg.fine_correspondence, sigma, cfg.independent_voxel
    )
    return PairResult(i, j, t, info, overlap, rmse, not reason, reason)


def select_pairs(poses: list[F64], max_distance: float) -> list[tuple[int, int]]:
    """Index pairs (i < j) of scans whose origins are within ``max_distance``."""
    xyz = np.array([p[:3, 3] for p in poses]).reshape(-1, 3)
    out = []
    for i in range(len(xyz)):
        for j in range(i + 1, len(xyz)):
            if np.linalg.norm(xyz[i] - xyz[j]) <= max_distance:
                out.append((i, j))
    return out


def prior_sigmas(cfg: RefineConfig) -> F64:
    """Sigmas of the navigation prior: (dx, dy, dz, rot_x, rot_y, rot_z) in m, rad."""
    tilt, yaw = math.radians(cfg.nav_sigma_tilt_deg), math.radians(cfg.nav_sigma_yaw_deg)
    return np.array([cfg.nav_sigma_xy, cfg.nav_sigma_xy, cfg.nav_sigma_z, tilt, tilt, yaw])


# aligns the pairs (i, j, navigation pose of j in i's frame) somewhere: their
# results in order (default: here, :func:`common.workers.starmap`)
PairsBy = Callable[[list[tuple[int, int, F64]]], list[PairResult]]


def refine(
    clouds: list[Prepared],
    nav: list[F64],
    cfg: RefineConfig,
    targets: list[TargetObservation] | None = None,
    pairs_by: PairsBy | None = None,
) -> tuple[list[F64], list[PairResult]]:
    """Refined poses (4x4 field <- scanner) of all scans and the pair results; sphere
    ``targets`` seen by two or more scans join the pose graph when ``cfg.use_targets``.
    The pairs are aligned ``cfg.threads`` at a time, each in its own process
    (:func:`common.workers.starmap`), or by ``pairs_by`` (a Dask cluster)."""
    if len(clouds) != len(nav):
        raise ValueError(f"{len(clouds)} clouds but {len(nav)} navigation poses")
    todo = [(i, j, inv(nav[i]) @ nav[j]) for i, j in select_pairs(nav, cfg.max_pair_distance)]
    if pairs_by is None:
        jobs = [(i, j, clouds[i], clouds[j], rel, cfg) for i, j, rel in todo]
        pairs = starmap(align_pair, jobs, cfg.threads)
    else:
        pairs = pairs_by(todo)
    for pr in pairs:
        log.info(
            "pair %d-%d: overlap %.2f rmse %.3f m %s",
            pr.i,
            pr.j,
            pr.overlap,
            pr.rmse,
            pr.reason or "ok",
        )
    obs = targets if cfg.use_targets else None
    return optimise_graph(nav, pairs, prior_sigmas(cfg), obs, cfg.target_sigma), pairs
