"""The paper's registration metrics ("Point cloud registration results", Table 1 and
the Hausdorff figure). All distances in metres, all frames ``field``.

- Target statistics: for every sphere observation (scan i, target k), the distance
  between the centre placed by a registration's pose, ``T_i c_ik``, and the target's
  reference position: mean 3D, mean horizontal and mean absolute vertical error.
- Scan point statistics: each scan's points (a uniform subsample) placed by the
  registration's pose and by the reference pose; the max and mean of the distances.
  Against the true poses this is the error against ground truth.
- Overlap residuals (what SCENE reports as a registration's "scan point statistics",
  and the paper's Table 1 quotes): for every pair of scans near enough to overlap,
  each scan's points placed by the registration's poses, and their point-to-plane
  distance to the nearest point of the other scan (its downsampled cloud with
  normals, the residual a cloud-to-cloud registration minimises), among those
  within a search radius; the mean over every such point and the largest pair
  mean. It needs no reference, so the target-based registration has one too (the
  paper's 1.37 cm): what is left when the poses are right is the clouds' own
  disagreement (ranging noise, a canopy seen from two sides), which is why it
  cannot be read as an error against the truth.
- Cloud-to-cloud (Hausdorff-style) distances from one cloud to the other: for every
  source point its nearest reference point; mean, SD, max (the Hausdorff distance),
  the shares below 2 and 3 cm, and the mean and SD of the per-axis components of
  the nearest-neighbour vectors (the paper's dH_X, dH_Y, dH_Z).
"""

from __future__ import annotations

import math

import msgspec
import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from common.arrays import I64
from common.poses import F64, apply, inv


class TargetStats(msgspec.Struct, frozen=True, kw_only=True):
    """Target errors (m) over ``count`` observations."""

    count: int
    mean: float
    horizontal: float
    vertical: float
    max: float


class PointStats(msgspec.Struct, frozen=True, kw_only=True):
    """Scan point errors (m) over ``count`` subsampled points, overall and per scan."""

    count: int
    max: float
    mean: float
    per_scan_mean: list[float]


class PairOverlap(msgspec.Struct, frozen=True, kw_only=True, array_like=True):
    """Scans ``i`` and ``j``: how many points of each found a neighbour of the other
    within the radius, and their mean point-to-plane distance (m)."""

    i: int
    j: int
    count: int
    mean: float


class OverlapStats(msgspec.Struct, frozen=True, kw_only=True):
    """Overlap residuals (m) within ``radius`` over ``count`` points of the
    ``pairs`` scan pairs that overlap: the mean over every point, the largest pair
    mean, and each pair."""

    radius: float
    count: int
    mean: float
    max: float
    pairs: list[PairOverlap]


class CloudDistance(msgspec.Struct, frozen=True, kw_only=True):
    """Nearest-neighbour distances (m) from a source cloud to a reference cloud."""

    count: int
    mean: float
    sd: float
    max: float
    below_2cm: float
    below_3cm: float
    axis_mean: tuple[float, float, float]
    axis_sd: tuple[float, float, float]


def target_stats(
    centres: list[F64], labels: list[I64], poses: list[F64], reference: F64
) -> TargetStats:
    """Errors of sphere centres ``centres[i]`` (scanner frame) with target ``labels[i]``
    (-1: skipped) placed by ``poses`` against target positions ``reference`` (K, 3)."""
    errs = []
    for c, lab, p in zip(centres, labels, poses, strict=True):
        m = np.asarray(lab) >= 0
        if m.any():
            errs.append(apply(p, np.asarray(c).reshape(-1, 3)[m]) - reference[np.asarray(lab)[m]])
    if not errs:
        nan = math.nan
        return TargetStats(count=0, mean=nan, horizontal=nan, vertical=nan, max=nan)
    e = np.vstack(errs)
    d = np.linalg.norm(e, axis=1)
    return TargetStats(
        count=len(e),
        mean=float(d.mean()),
        horizontal=float(np.hypot(e[:, 0], e[:, 1]).mean()),
        vertical=float(np.abs(e[:, 2]).mean()),
        max=float(d.max()),
    )


def subsample(points: F64, n: int, rng: np.random.Generator) -> F64:
    """At most ``n`` points drawn uniformly without replacement."""
    if len(points) <= n:
        return points
    out: F64 = points[rng.choice(len(points), n, replace=False)]
    return out


def point_stats(samples: list[F64], poses: list[F64], reference: list[F64]) -> PointStats:
    """Scan point errors of ``poses`` against ``reference`` poses on per-scan point
    samples (scanner frame)."""
    per, alld = [], []
    for s, p, r in zip(samples, poses, reference, strict=True):
        d = np.linalg.norm(apply(p, s) - apply(r, s), axis=1)
        per.append(float(d.mean()) if len(d) else math.nan)
        alld.append(d)
    d = np.concatenate(alld) if alld else np.zeros(0)
    if len(d) == 0:
        return PointStats(count=0, max=math.nan, mean=math.nan, per_scan_mean=per)
    return PointStats(count=len(d), max=float(d.max()), mean=float(d.mean()), per_scan_mean=per)


def overlap_stats(
    clouds: list[tuple[F64, F64, cKDTree]],
    samples: list[F64],
    poses: list[F64],
    pairs: list[tuple[int, int]],
    radius: float,
    min_points: int = 50,
) -> OverlapStats:
    """Overlap residuals of ``poses`` (field <- scanner) over scan ``pairs``: each
    scan's ``samples`` (scanner frame) placed into the other scan's frame, matched to
    the nearest point of its downsampled cloud (``clouds``: points, unit normals and
    their k-d tree, scanner frame, built once for every method) within ``radius``,
    and measured along that point's normal. A pair overlaps when at least
    ``min_points`` points matched."""
    per: list[PairOverlap] = []
    dists: list[npt.NDArray[np.float64]] = []
    for i, j in pairs:
        d = []
        for a, b in ((i, j), (j, i)):
            points, normals, tree = clouds[a]
            pts = apply(inv(poses[a]) @ poses[b], samples[b])
            da, k = tree.query(pts, distance_upper_bound=radius)
            m = np.isfinite(da)
            d.append(np.abs(np.einsum("ij,ij->i", pts[m] - points[k[m]], normals[k[m]])))
        both = np.concatenate(d)
        if len(both) >= min_points:
            per.append(PairOverlap(i=i, j=j, count=len(both), mean=float(both.mean())))
            dists.append(both)
    if not dists:
        return OverlapStats(radius=radius, count=0, mean=math.nan, max=math.nan, pairs=[])
    alld = np.concatenate(dists)
    return OverlapStats(
        radius=radius,
        count=len(alld),
        mean=float(alld.mean()),
        max=max(p.mean for p in per),
        pairs=per,
    )


def cloud_distance(source: F64, reference: F64, tree: cKDTree | None = None) -> CloudDistance:
    """Nearest-neighbour distances from every ``source`` point to ``reference`` (both
    (N, 3), field frame); ``tree``: the k-d tree of ``reference`` when the caller keeps
    one for several sources (millions of points take seconds to index). Raises
    ValueError for an empty cloud."""
    if len(source) == 0 or len(reference) == 0:
        raise ValueError(f"cloud distance of empty clouds ({len(source)}, {len(reference)})")
    d, k = (cKDTree(reference) if tree is None else tree).query(source, workers=1)
    vec = source - reference[k]
    return CloudDistance(
        count=len(d),
        mean=float(d.mean()),
        sd=float(d.std()),
        max=float(d.max()),
        below_2cm=float((d < 0.02).mean()),
        below_3cm=float((d < 0.03).mean()),
        axis_mean=(float(vec[:, 0].mean()), float(vec[:, 1].mean()), float(vec[:, 2].mean())),
        axis_sd=(float(vec[:, 0].std()), float(vec[:, 1].std()), float(vec[:, 2].std())),
    )


def merged(samples: list[F64], poses: list[F64]) -> F64:
    """All samples placed by their poses, stacked (field frame)."""
    return np.vstack([apply(p, s) for s, p in zip(samples, poses, strict=True)])
