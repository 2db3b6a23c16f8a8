"""First-hit ray casting into the simulated world (numba, parallel over rays).

A :class:`Scene` holds everything a ray can hit, in the ``field`` frame: the terrain
heightfield, the per-plot foliage voxel grids, spheres, vertical cylinders (poles,
obstacle posts) and solid boxes (obstacles, or plot boxes for the 2D lidar). Each
ray returns its distance, a surface label (:data:`GROUND` ...) and the unit surface
normal at the hit. Objects are few (tens), so each ray tests them all; foliage grids
are walked voxel by voxel (Amanatides-Woo) only where the ray crosses them.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numba as nb
import numpy as np
import numpy.typing as npt

from common.arrays import F64, U8
from services.sim.foliage import LEAF, STEM, Foliage
from services.sim.terrain import Terrain, bilinear_height, ray_terrain

_JIT: dict[str, Any] = {"cache": True, "error_model": "numpy"}

NONE, GROUND, LEAF_HIT, STEM_HIT, SPHERE, POLE, OBSTACLE, PLOT = 0, 1, 2, 3, 4, 5, 6, 7
LABEL_NAMES = ("none", "ground", "leaf", "stem", "sphere", "pole", "obstacle", "plot")
_FOLIAGE_LABEL = {LEAF: LEAF_HIT, STEM: STEM_HIT}


@dataclasses.dataclass(frozen=True, eq=False)
class Scene:
    """What rays can hit. ``spheres`` (S, 5) [cx, cy, cz, r, label]; ``cylinders``
    (C, 6) [x, y, zlo, zhi, r, label], vertical with a top cap; ``boxes`` (B, 7)
    [xmin, ymin, zmin, xmax, ymax, zmax, label]. ``foliage`` None: no plants."""

    terrain: Terrain | None
    foliage: Foliage | None
    spheres: F64
    cylinders: F64
    boxes: F64

    def cast(self, origin: npt.ArrayLike, dirs: F64, tmax: float) -> tuple[F64, U8, F64]:
        """Distances (N,) (inf: no hit within ``tmax``), labels (N,) and unit normals
        (N, 3) of unit rays ``dirs`` (N, 3) from one ``origin`` (3,), field frame."""
        o = np.ascontiguousarray(origin, dtype=np.float64).reshape(3)
        d = np.ascontiguousarray(dirs, dtype=np.float64).reshape(-1, 3)
        ter = self.terrain
        grid = ter.grid if ter is not None else np.zeros((2, 2))
        tpar = (
            np.array([ter.x0, ter.y0, ter.spacing, ter.hmin, ter.hmax, 1.0])
            if ter is not None
            else np.zeros(6)
        )
        fol = self.foliage
        if fol is not None:
            lut = np.zeros(256, dtype=np.uint8)
            for k, v in _FOLIAGE_LABEL.items():
                lut[k] = v
            forg, fdims, foff, focc = fol.origin, fol.dims, fol.offset, fol.occ
            fvox = fol.voxel
        else:
            lut = np.zeros(256, dtype=np.uint8)
            forg, fdims = np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
            foff, focc, fvox = np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.uint8), 1.0
        t = np.empty(len(d))
        lab = np.empty(len(d), dtype=np.uint8)
        nrm = np.empty((len(d), 3))
        _cast_all(
            o,
            d,
            float(tmax),
            grid,
            tpar,
            forg,
            fdims,
            foff,
            focc,
            fvox,
            lut,
            _f64(self.spheres, 5),
            _f64(self.cylinders, 6),
            _f64(self.boxes, 7),
            t,
            lab,
            nrm,
        )
        return t, lab, nrm


def _f64(a: F64, cols: int) -> F64:
    return np.ascontiguousarray(np.asarray(a, dtype=np.float64).reshape(-1, cols))


@nb.njit(**_JIT)
def _slab(o: F64, d: F64, lo: F64, hi: F64) -> tuple[float, float, int]:
    """Entry and exit distances of a ray through an AABB and the entry axis."""
    tn, tf, ax = -np.inf, np.inf, -1
    for a in range(3):
        if d[a] == 0.0:
            if o[a] < lo[a] or o[a] > hi[a]:
                return np.inf, -np.inf, -1
            continue
        t1, t2 = (lo[a] - o[a]) / d[a], (hi[a] - o[a]) / d[a]
        if t1 > t2:
            t1, t2 = t2, t1
        if t1 > tn:
            tn, ax = t1, a
        tf = min(tf, t2)
    return tn, tf, ax


@nb.njit(**_JIT)
def _voxels(
    o: F64,
    d: F64,
    lo: F64,
    n: npt.NDArray[np.int64],
    occ: U8,
    off: int,
    vox: float,
    tn: float,
    tf: float,
    ax: int,
    best: float,
    nrm: F64,
) -> tuple[float, int]:
    """Walk one foliage grid from ``tn`` to min(tf, best); (t, voxel value) of the
    first occupied voxel, or (best, 0)."""
    t = max(tn, 0.0)
    if t > 0.0:
        t += 1e-9
    idx = np.empty(3, dtype=np.int64)
    stp = np.empty(3, dtype=np.int64)
    tmx = np.empty(3)
    tdl = np.empty(3)
    for a in range(3):
        idx[a] = min(max(math.floor((o[a] + d[a] * t - lo[a]) / vox), 0), n[a] - 1)
        if d[a] > 0:
            stp[a], tmx[a], tdl[a] = 1, (lo[a] + (idx[a] + 1) * vox - o[a]) / d[a], vox / d[a]
        elif d[a] < 0:
            stp[a], tmx[a], tdl[a] = -1, (lo[a] + idx[a] * vox - o[a]) / d[a], -vox / d[a]
        else:
            stp[a], tmx[a], tdl[a] = 0, np.inf, np.inf
    tend = min(tf, best)
    t = max(tn, 0.0)
    while t <= tend:
        v = occ[off + (idx[0] * n[1] + idx[1]) * n[2] + idx[2]]
        if v != 0:
            if ax >= 0:
                nrm[0], nrm[1], nrm[2] = 0.0, 0.0, 0.0
                nrm[ax] = -1.0 if d[ax] > 0 else 1.0
            else:
                nrm[0], nrm[1], nrm[2] = -d[0], -d[1], -d[2]
            return t, v
        a = 0
        if tmx[1] < tmx[a]:
            a = 1
        if tmx[2] < tmx[a]:
            a = 2
        t = tmx[a]
        idx[a] += stp[a]
        if idx[a] < 0 or idx[a] >= n[a]:
            break
        tmx[a] += tdl[a]
        ax = a
    return best, 0


@nb.njit(**_JIT)
def _first_hit(  # noqa: C901, PLR0915
    o: F64,
    d: F64,
    tmax: float,
    grid: F64,
    tpar: F64,
    forg: F64,
    fdims: npt.NDArray[np.int64],
    foff: npt.NDArray[np.int64],
    focc: U8,
    fvox: float,
    lut: U8,
    sph: F64,
    cyl: F64,
    box: F64,
    nrm: F64,
) -> tuple[float, int]:
    best, lab = tmax, 0
    if tpar[5] > 0.0:
        t = ray_terrain(grid, tpar[0], tpar[1], tpar[2], tpar[3], tpar[4], o, d, best)
        if t < best:
            best, lab = t, GROUND
            p0, p1 = o[0] + d[0] * t, o[1] + d[1] * t
            # normal of the bilinear patch by central differences of the height
            e = 0.25 * tpar[2]
            hx = ray_height(grid, tpar, p0 + e, p1) - ray_height(grid, tpar, p0 - e, p1)
            hy = ray_height(grid, tpar, p0, p1 + e) - ray_height(grid, tpar, p0, p1 - e)
            nx, ny, nz = -hx / (2 * e), -hy / (2 * e), 1.0
            s = math.sqrt(nx * nx + ny * ny + nz * nz)
            nrm[0], nrm[1], nrm[2] = nx / s, ny / s, nz / s
    tmp = np.empty(3)
    hi = np.empty(3)
    for p in range(forg.shape[0]):
        for a in range(3):
            hi[a] = forg[p, a] + fdims[p, a] * fvox
        tn, tf, ax = _slab(o, d, forg[p], hi)
        if tn > tf or tf < 0.0 or tn >= best:
            continue
        t, v = _voxels(o, d, forg[p], fdims[p], focc, foff[p], fvox, tn, tf, ax, best, tmp)
        if v != 0 and t < best:
            best, lab = t, lut[v]
            nrm[0], nrm[1], nrm[2] = tmp[0], tmp[1], tmp[2]
    for k in range(sph.shape[0]):
        ox, oy, oz = o[0] - sph[k, 0], o[1] - sph[k, 1], o[2] - sph[k, 2]
        b = ox * d[0] + oy * d[1] + oz * d[2]
        c = ox * ox + oy * oy + oz * oz - sph[k, 3] ** 2
        disc = b * b - c
        if disc < 0.0:
            continue
        t = -b - math.sqrt(disc)
        if t < 0.0:
            t = -b + math.sqrt(disc)
        if 0.0 <= t < best:
            best, lab = t, int(sph[k, 4])
            for a in range(3):
                nrm[a] = (o[a] + d[a] * t - sph[k, a]) / sph[k, 3]
    for k in range(cyl.shape[0]):
        cx, cy, zlo, zhi, r = cyl[k, 0], cyl[k, 1], cyl[k, 2], cyl[k, 3], cyl[k, 4]
        ox, oy = o[0] - cx, o[1] - cy
        aa = d[0] * d[0] + d[1] * d[1]
        if aa > 1e-18:
            b = ox * d[0] + oy * d[1]
            disc = b * b - aa * (ox * ox + oy * oy - r * r)
            if disc >= 0.0:
                t = (-b - math.sqrt(disc)) / aa
                z = o[2] + d[2] * t
                if 0.0 <= t < best and zlo <= z <= zhi:
                    best, lab = t, int(cyl[k, 5])
                    nrm[0], nrm[1], nrm[2] = (ox + d[0] * t) / r, (oy + d[1] * t) / r, 0.0
        if d[2] < 0.0:
            t = (zhi - o[2]) / d[2]
            px, py = ox + d[0] * t, oy + d[1] * t
            if 0.0 <= t < best and px * px + py * py <= r * r:
                best, lab = t, int(cyl[k, 5])
                nrm[0], nrm[1], nrm[2] = 0.0, 0.0, 1.0
    for k in range(box.shape[0]):
        tn, tf, ax = _slab(o, d, box[k, 0:3], box[k, 3:6])
        if tn <= tf and tn >= 0.0 and tn < best and ax >= 0:
            best, lab = tn, int(box[k, 6])
            nrm[0], nrm[1], nrm[2] = 0.0, 0.0, 0.0
            nrm[ax] = -1.0 if d[ax] > 0 else 1.0
    if lab == 0:
        return np.inf, 0
    return best, lab


@nb.njit(**_JIT)
def ray_height(grid: F64, tpar: F64, x: float, y: float) -> float:
    return bilinear_height(grid, tpar[0], tpar[1], tpar[2], x, y)


@nb.njit(parallel=True, **_JIT)
def _cast_all(
    o: F64,
    dirs: F64,
    tmax: float,
    grid: F64,
    tpar: F64,
    forg: F64,
    fdims: npt.NDArray[np.int64],
    foff: npt.NDArray[np.int64],
    focc: U8,
    fvox: float,
    lut: U8,
    sph: F64,
    cyl: F64,
    box: F64,
    t_out: F64,
    lab_out: U8,
    nrm_out: F64,
) -> None:
    for i in nb.prange(dirs.shape[0]):
        nrm = np.zeros(3)
        t, lab = _first_hit(
            o, dirs[i], tmax, grid, tpar, forg, fdims, foff, focc, fvox, lut, sph, cyl, box, nrm
        )
        t_out[i] = t
        lab_out[i] = lab
        nrm_out[i, 0], nrm_out[i, 1], nrm_out[i, 2] = nrm[0], nrm[1], nrm[2]
