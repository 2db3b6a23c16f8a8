"""Find and fit the 200 mm registration spheres in one scan.

Detection: the white spheres are the brightest surfaces of a field scan (0.85
reflectivity against 0.25-0.55 for leaves, soil and aluminium poles), so points with
an intensity of at least ``min_intensity`` seed candidates; seeds are grouped by
proximity, every point near a group is gathered, and a RANSAC fit with the known
radius followed by a least-squares fit decides whether it is a sphere. Scans without
intensity (all zero) give no candidates.

Fitting: :func:`fit_sphere` minimises the geometric residual ``|p - c| - r`` by
Levenberg-Marquardt (scipy's ``least_squares``), with the radius known or free. A
scanner sees only the near cap of a sphere, so the centre is started behind the
visible surface as seen from the scanner (the frame origin).

All coordinates are in the frame of the points given (the ``scanner`` frame for a
scan), metres.
"""

from __future__ import annotations

import dataclasses
from typing import Annotated

import msgspec
import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from common.arrays import F64
from common.messages.core import NonNegative, Positive


class SphereConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Sphere detection (``[register.spheres]``). The defaults suit Koppa 200 mm spheres
    scanned at the paper's 0.36 deg step (6 mm at 1 m): ~8 points on a sphere at 10 m."""

    radius: Positive = 0.1
    """The spheres' radius (m)."""
    min_intensity: NonNegative = 0.6
    """Points at least this bright (intensity 0-1) seed candidates."""
    min_points: Annotated[int, msgspec.Meta(ge=4)] = 6
    """The fewest points a sphere is found from."""
    inlier_threshold: Positive = 0.006
    """The inlier band of the RANSAC fit (m)."""
    max_rms: Positive = 0.004
    """The largest accepted RMS residual of a fit (m)."""
    radius_tolerance: Positive = 0.015
    """A free-radius fit must agree with ``radius`` this well (m)."""
    free_fit_points: Annotated[int, msgspec.Meta(ge=4)] = 30
    """A free-radius fit is made when a sphere has at least this many points."""
    ransac_iterations: Annotated[int, msgspec.Meta(ge=1)] = 200
    """RANSAC's iterations per candidate."""
    max_range: Positive = 40.0
    """Spheres are looked for within this distance of the scanner (m)."""


@dataclasses.dataclass(frozen=True)
class SphereFit:
    """A fitted sphere: centre (3,), radius, RMS of ``|p - c| - r`` and the number of
    points used (m)."""

    centre: F64
    radius: float
    rms: float
    n: int


class SphereFitError(ValueError):
    """Too few or degenerate points for a sphere fit."""


def fit_sphere(
    points: F64, radius: float | None = None, init: F64 | None = None, iterations: int = 30
) -> SphereFit:
    """Least-squares sphere through ``points`` (N, 3): known ``radius`` or free
    (None). ``init``: a starting centre (default: behind the cap, seen from the
    origin). Raises SphereFitError for fewer than 4 (free: 5) points or a
    degenerate fit."""
    pts = np.asarray(points, dtype=np.float64)
    need = 4 if radius is not None else 5
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < need:
        raise SphereFitError(f"sphere fit needs >= {need} points (N, 3), got {pts.shape}")
    mean = pts.mean(axis=0)
    if init is None:
        r0 = radius if radius is not None else _algebraic_radius(pts)
        view = mean / max(float(np.linalg.norm(mean)), 1e-9)
        init = mean + view * 0.7 * r0
    c0 = np.asarray(init, dtype=np.float64)
    r0 = float(radius) if radius is not None else float(np.linalg.norm(pts - c0, axis=1).mean())
    x0 = c0 if radius is not None else np.append(c0, r0)

    def residuals(x: F64) -> F64:
        r = r0 if radius is not None else x[3]
        return np.asarray(np.linalg.norm(pts - x[:3], axis=1) - r)

    def jacobian(x: F64) -> F64:
        d = pts - x[:3]
        dist = np.linalg.norm(d, axis=1)
        if np.any(dist < 1e-12):
            raise SphereFitError("sphere fit: a point coincides with the centre")
        u = d / dist[:, None]
        return -u if radius is not None else np.column_stack([-u, -np.ones(len(pts))])

    # Levenberg-Marquardt (MINPACK) on the geometric distances
    sol = least_squares(residuals, x0, jac=jacobian, method="lm", max_nfev=iterations * 4)
    c, r = sol.x[:3], (r0 if radius is not None else float(sol.x[3]))
    res = np.linalg.norm(pts - c, axis=1) - r
    if not (np.all(np.isfinite(c)) and r > 0):
        raise SphereFitError("sphere fit diverged")
    return SphereFit(c, r, float(np.sqrt(np.mean(res**2))), len(pts))


def _algebraic_radius(pts: F64) -> float:
    """Radius of the linear fit ``|p|^2 = 2 c.p + k`` (a start for the free fit)."""
    a = np.column_stack([2 * pts, np.ones(len(pts))])
    sol, *_ = np.linalg.lstsq(a, (pts**2).sum(axis=1), rcond=None)
    return float(np.sqrt(max(sol[3] + sol[:3] @ sol[:3], 1e-12)))


def ransac_sphere(
    points: F64,
    radius: float,
    threshold: float,
    rng: np.random.Generator,
    iterations: int = 200,
) -> tuple[F64, npt.NDArray[np.bool_]]:
    """Centre with the most inliers (``||p - c| - radius| < threshold``) over
    centres through 3 random points with the known radius, and that inlier mask.
    Of the two centres through 3 points, the one farther from the origin (the
    scanner) is taken: a scanner sees the near side. Raises SphereFitError for fewer
    than 3 points or when no sample gives a centre."""
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) < 3:
        raise SphereFitError(f"RANSAC needs >= 3 points, got {len(pts)}")
    idx = np.array([rng.choice(len(pts), 3, replace=False) for _ in range(iterations)])
    a, b, c = pts[idx[:, 0]], pts[idx[:, 1]], pts[idx[:, 2]]
    ab, ac = b - a, c - a
    n = np.cross(ab, ac)
    nn = np.einsum("ij,ij->i", n, n)
    ok = nn > 1e-14
    # circumcentre of the triangle, then up or down its normal to the known radius
    num = np.cross(
        np.einsum("ij,ij->i", ab, ab)[:, None] * ac - np.einsum("ij,ij->i", ac, ac)[:, None] * ab,
        n,
    )
    with np.errstate(divide="ignore", invalid="ignore"):
        cc = a + num / (2 * nn[:, None])
        rc2 = np.einsum("ij,ij->i", cc - a, cc - a)
        h = np.sqrt(np.maximum(radius**2 - rc2, 0.0))
        un = n / np.sqrt(nn)[:, None]
    ok &= rc2 <= radius**2 * 1.0001
    cand = np.where(
        (np.einsum("ij,ij->i", un, cc) >= 0)[:, None], cc + h[:, None] * un, cc - h[:, None] * un
    )[ok]
    if len(cand) == 0:
        raise SphereFitError("RANSAC found no sphere of the given radius")
    dist = np.abs(np.linalg.norm(pts[None, :, :] - cand[:, None, :], axis=2) - radius)
    score = (dist < threshold).sum(axis=1)
    best = int(np.argmax(score))
    return cand[best], dist[best] < threshold


@dataclasses.dataclass(frozen=True)
class SphereDetection:
    """A sphere found in a scan: the known-radius fit (centre in the scan's frame),
    the free-radius estimate (NaN when too few points) and the point indices."""

    fit: SphereFit
    free_radius: float
    indices: npt.NDArray[np.int64]


def detect_spheres(
    points: F64,
    intensity: npt.ArrayLike,
    cfg: SphereConfig | None = None,
    rng: np.random.Generator | None = None,
) -> list[SphereDetection]:
    """Spheres of radius ``cfg.radius`` in a scan (points (N, 3) in the scanner frame,
    intensity (N,) in [0, 1]); see the module docstring. Raises ValueError when
    the shapes do not match."""
    cfg = cfg or SphereConfig()
    rng = rng or np.random.default_rng(0)
    pts = np.asarray(points, dtype=np.float64)
    inten = np.asarray(intensity, dtype=np.float64).ravel()
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) != len(inten):
        raise ValueError(f"points {pts.shape} and intensity {inten.shape} do not match")
    near = np.linalg.norm(pts, axis=1) <= cfg.max_range
    seeds = np.flatnonzero((inten >= cfg.min_intensity) & near)
    if len(seeds) < cfg.min_points // 2:
        return []
    r = cfg.radius
    tree_s = cKDTree(pts[seeds])
    n_groups, labels = connected_components(
        tree_s.sparse_distance_matrix(tree_s, r, output_type="coo_matrix")
    )
    tree = cKDTree(pts)
    found: list[SphereDetection] = []
    for g in range(n_groups):
        grp = pts[seeds[labels == g]]
        if len(grp) < 2 or np.ptp(grp, axis=0).max() > 2.2 * r:
            continue
        idx = np.asarray(tree.query_ball_point(grp.mean(axis=0), 1.6 * r), dtype=np.int64)
        if len(idx) < cfg.min_points:
            continue
        det = _fit_candidate(pts, idx, cfg, rng)
        if det is not None and all(
            np.linalg.norm(det.fit.centre - o.fit.centre) > r for o in found
        ):
            found.append(det)
    return found


def _fit_candidate(
    pts: F64, idx: npt.NDArray[np.int64], cfg: SphereConfig, rng: np.random.Generator
) -> SphereDetection | None:
    r = cfg.radius
    try:
        c0, inl = ransac_sphere(pts[idx], r, cfg.inlier_threshold, rng, cfg.ransac_iterations)
        if inl.sum() < cfg.min_points:
            return None
        fit = fit_sphere(pts[idx[inl]], r, init=c0)
        # re-gather inliers around the refined centre (RANSAC's band may be off by noise)
        d = np.abs(np.linalg.norm(pts[idx] - fit.centre, axis=1) - r)
        keep = idx[d < cfg.inlier_threshold]
        if len(keep) < cfg.min_points:
            return None
        fit = fit_sphere(pts[keep], r, init=fit.centre)
    except SphereFitError:
        return None
    if fit.rms > cfg.max_rms:
        return None
    free = float("nan")
    if len(keep) >= cfg.free_fit_points:
        try:
            free = fit_sphere(pts[keep], None, init=fit.centre).radius
        except SphereFitError:
            return None
        if abs(free - r) > cfg.radius_tolerance:
            return None
    return SphereDetection(fit, free, keep)
