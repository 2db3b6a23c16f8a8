"""Bare ground of the simulated field: a smooth heightfield in the ``field`` frame.

The surface is a plane (a gentle slope) plus smoothed Gaussian noise (bumps a few
centimetres high and a few metres across), sampled on a regular grid over the field
bounds plus a margin and bilinearly interpolated between samples. The grid is the one
truth: the robot's wheels, the scanner's rays and the lidar all read the same bilinear
surface, so they never disagree by an interpolation error. Outside the grid the height
is clamped to the nearest edge sample; rays leave the world there (no ground return).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Annotated, Any

import msgspec
import numba as nb
import numpy as np
import numpy.typing as npt
from scipy.ndimage import gaussian_filter

from common.arrays import F64
from common.messages.core import Finite

_JIT: dict[str, Any] = {"cache": True, "error_model": "numpy"}


class TerrainConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Ground shape (metres, percent, degrees).

    Defaults are assumptions, not measurements: the paper reports only that "terrain
    slope, bumps, or other surface irregularities" tilted the robot beyond the scanner
    compensator's +-2 deg, so the slope is a gentle 1 % (typical of drained farm fields)
    and the bumps have a 3 cm RMS height with a 1.5 m correlation length (ridges and
    wheel ruts a few metres apart), which gives robot pitch/roll of about a degree.
    """

    slope_pct: Annotated[float, msgspec.Meta(ge=0, le=30)] = 1.0
    """The ground's slope (%)."""
    slope_dir_deg: Finite = 30.0
    """The direction the ground rises towards, degrees CCW from the field +x axis."""
    bump_rms: Annotated[float, msgspec.Meta(ge=0, le=1)] = 0.03
    """The bumps' RMS height (m)."""
    bump_length: Annotated[float, msgspec.Meta(gt=0, le=100)] = 1.5
    """The bumps' correlation length (m)."""
    margin: Annotated[float, msgspec.Meta(ge=0, le=200)] = 25.0
    """Ground beyond the field boundary (m): 25 m is enough for every ground return of
    a scanner at 1 m height inside the field down to ~2 deg below horizontal."""
    spacing: Annotated[float, msgspec.Meta(gt=0.01, le=2)] = 0.2
    """The height grid's spacing (m)."""


@dataclasses.dataclass(frozen=True, eq=False)
class Terrain:
    """Heights ``grid[i, j]`` (m) at ``(x0 + i * spacing, y0 + j * spacing)`` in the
    ``field`` frame; ``hmin``/``hmax`` bound the whole surface (for ray clipping)."""

    grid: F64
    x0: float
    y0: float
    spacing: float
    hmin: float
    hmax: float

    def height(self, x: npt.ArrayLike, y: npt.ArrayLike) -> F64:
        """Ground height (m) at field-frame points, vectorised over broadcast x, y."""
        xa, ya = np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(y, np.float64))
        out = np.empty(xa.shape)
        _height_many(self.grid, self.x0, self.y0, self.spacing, xa.ravel(), ya.ravel(), out.ravel())
        return out

    def normal(self, x: npt.ArrayLike, y: npt.ArrayLike) -> F64:
        """Unit upward surface normals, shape ``broadcast(x, y).shape + (3,)``."""
        xa, ya = np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(y, np.float64))
        g = np.empty((xa.size, 2))
        _gradient_many(self.grid, self.x0, self.y0, self.spacing, xa.ravel(), ya.ravel(), g)
        n = np.stack([-g[:, 0], -g[:, 1], np.ones(len(g))], axis=1)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        return n.reshape((*xa.shape, 3))


def build_terrain(bounds: F64, cfg: TerrainConfig, seed: int) -> Terrain:
    """The ground over ``bounds`` = [xmin, ymin, xmax, ymax] (field frame) plus
    ``cfg.margin``; the height is 0 at the field's centre, so plot boxes (z from 0) sit
    on the ground on average."""
    xmin, ymin, xmax, ymax = (float(b) for b in bounds)
    x0, y0 = xmin - cfg.margin, ymin - cfg.margin
    nx = math.ceil((xmax + cfg.margin - x0) / cfg.spacing) + 1
    ny = math.ceil((ymax + cfg.margin - y0) / cfg.spacing) + 1
    gx = x0 + np.arange(nx) * cfg.spacing
    gy = y0 + np.arange(ny) * cfg.spacing
    cx, cy = (xmin + xmax) / 2, (ymin + ymax) / 2
    a = math.radians(cfg.slope_dir_deg)
    s = cfg.slope_pct / 100.0
    plane = s * (math.cos(a) * (gx[:, None] - cx) + math.sin(a) * (gy[None, :] - cy))
    bumps = np.zeros((nx, ny))
    if cfg.bump_rms > 0:
        rng = np.random.default_rng(np.random.SeedSequence([seed, 0x7E44]))
        noise = rng.standard_normal((nx, ny))
        bumps = gaussian_filter(noise, sigma=cfg.bump_length / cfg.spacing, mode="reflect")
        bumps *= cfg.bump_rms / max(float(bumps.std()), 1e-12)
    grid = np.ascontiguousarray(plane + bumps)
    grid -= bilinear_height(grid, x0, y0, cfg.spacing, cx, cy)
    return Terrain(grid, x0, y0, cfg.spacing, float(grid.min()), float(grid.max()))


@nb.njit(**_JIT)
def _cell(
    grid: F64, x0: float, y0: float, s: float, x: float, y: float
) -> tuple[int, int, float, float]:
    """Grid cell (i, j) holding (x, y), clamped to the grid, and the offsets in it."""
    nx, ny = grid.shape
    u = min(max((x - x0) / s, 0.0), nx - 1.000001)
    v = min(max((y - y0) / s, 0.0), ny - 1.000001)
    i, j = int(u), int(v)
    return i, j, u - i, v - j


@nb.njit(**_JIT)
def bilinear_height(grid: F64, x0: float, y0: float, s: float, x: float, y: float) -> float:
    i, j, fu, fv = _cell(grid, x0, y0, s, x, y)
    h0 = grid[i, j] * (1 - fu) + grid[i + 1, j] * fu
    h1 = grid[i, j + 1] * (1 - fu) + grid[i + 1, j + 1] * fu
    return float(h0 * (1 - fv) + h1 * fv)


@nb.njit(**_JIT)
def _gradient(grid: F64, x0: float, y0: float, s: float, x: float, y: float) -> tuple[float, float]:
    """(dh/dx, dh/dy) of the bilinear patch at (x, y); 0 along clamped axes outside."""
    i, j, fu, fv = _cell(grid, x0, y0, s, x, y)
    nx, ny = grid.shape
    gx = ((grid[i + 1, j] - grid[i, j]) * (1 - fv) + (grid[i + 1, j + 1] - grid[i, j + 1]) * fv) / s
    gy = ((grid[i, j + 1] - grid[i, j]) * (1 - fu) + (grid[i + 1, j + 1] - grid[i + 1, j]) * fu) / s
    if x < x0 or x > x0 + (nx - 1) * s:
        gx = 0.0
    if y < y0 or y > y0 + (ny - 1) * s:
        gy = 0.0
    return gx, gy


@nb.njit(**_JIT)
def _height_many(grid: F64, x0: float, y0: float, s: float, xs: F64, ys: F64, out: F64) -> None:
    for k in range(xs.size):
        out[k] = bilinear_height(grid, x0, y0, s, xs[k], ys[k])


@nb.njit(**_JIT)
def _gradient_many(grid: F64, x0: float, y0: float, s: float, xs: F64, ys: F64, out: F64) -> None:
    for k in range(xs.size):
        out[k, 0], out[k, 1] = _gradient(grid, x0, y0, s, xs[k], ys[k])


@nb.njit(**_JIT)
def _above(grid: F64, x0: float, y0: float, s: float, o: F64, d: F64, t: float) -> float:
    """Height of the ray point at ``t`` above the ground under it."""
    return o[2] + d[2] * t - bilinear_height(grid, x0, y0, s, o[0] + d[0] * t, o[1] + d[1] * t)


@nb.njit(**_JIT)
def ray_terrain(
    grid: F64,
    x0: float,
    y0: float,
    s: float,
    hmin: float,
    hmax: float,
    o: F64,
    d: F64,
    tmax: float,
) -> float:
    """Distance along unit ray ``o + t d`` to the ground (first crossing), or inf.

    Marches in steps of half a grid cell in xy, brackets the first sign change of
    ``z(t) - h(t)`` and bisects it to ~1e-6 of a step; rays that leave the grid xy
    extent or rise above ``hmax`` miss.
    """
    nx, ny = grid.shape
    t0, t1 = 0.0, tmax
    # clip to the grid's xy slab
    for a, lo, hi in ((0, x0, x0 + (nx - 1) * s), (1, y0, y0 + (ny - 1) * s)):
        if abs(d[a]) < 1e-12:
            if o[a] < lo or o[a] > hi:
                return np.inf
        else:
            ta, tb = (lo - o[a]) / d[a], (hi - o[a]) / d[a]
            t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
    # clip to the height band [hmin, hmax]
    if d[2] < 0:
        if o[2] > hmax:
            t0 = max(t0, (hmax - o[2]) / d[2])
        t1 = min(t1, (hmin - 1e-9 - o[2]) / d[2])
    elif d[2] > 0:
        if o[2] > hmax:
            return np.inf
        t1 = min(t1, (hmax - o[2]) / d[2])
    elif o[2] > hmax:
        return np.inf
    if t1 <= t0:
        return np.inf
    horiz = math.hypot(d[0], d[1])
    dt = min(0.5 * s / max(horiz, 1e-9), 0.5, t1 - t0)
    ta = t0
    fa = _above(grid, x0, y0, s, o, d, ta)
    if fa <= 0.0:
        return ta
    while ta < t1:
        tb = min(ta + dt, t1)
        fb = _above(grid, x0, y0, s, o, d, tb)
        if fb <= 0.0:
            for _ in range(30):
                tm = 0.5 * (ta + tb)
                if _above(grid, x0, y0, s, o, d, tm) > 0.0:
                    ta = tm
                else:
                    tb = tm
            return tb
        ta, fa = tb, fb
    return np.inf
