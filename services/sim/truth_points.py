"""A dense, deterministic sample of every true surface of the simulated world, for
scoring registrations cloud-to-truth (evaluation only; :mod:`services.sim.world`
builds the world)."""

from __future__ import annotations

import math

import numpy as np

from common.arrays import F64, U8
from common.field import Field
from services.sim.foliage import EMPTY, STEM, Foliage
from services.sim.scene import GROUND, LEAF_HIT, POLE, SPHERE, STEM_HIT
from services.sim.targets import Targets
from services.sim.terrain import Terrain


def truth_points(
    field: Field, terrain: Terrain, foliage: Foliage, targets: Targets, spacing: float = 0.05
) -> tuple[F64, U8]:
    """Points (field frame, m) with labels: ground on a ``spacing`` grid over the field
    bounds, the exposed foliage voxels (centres of occupied voxels with an empty
    face-neighbour), and sphere and pole surfaces at about ``spacing``."""
    if not spacing > 0:
        raise ValueError(f"spacing must be > 0 m, got {spacing}")
    xmin, ymin, xmax, ymax = field.bounds
    gx, gy = np.meshgrid(np.arange(xmin, xmax, spacing), np.arange(ymin, ymax, spacing))
    parts = [np.column_stack([gx.ravel(), gy.ravel(), terrain.height(gx, gy).ravel()])]
    labels = [np.full(gx.size, GROUND, np.uint8)]
    fol = foliage
    for p in range(fol.n_plots):
        g = fol.grid(p)
        occ = g != EMPTY
        pad = np.pad(occ, 1, constant_values=False)
        inner = pad[2:, 1:-1, 1:-1] & pad[:-2, 1:-1, 1:-1] & pad[1:-1, 2:, 1:-1]
        inner &= pad[1:-1, :-2, 1:-1] & pad[1:-1, 1:-1, 2:] & pad[1:-1, 1:-1, :-2]
        idx = np.argwhere(occ & ~inner)
        parts.append(fol.origin[p] + (idx + 0.5) * fol.voxel)
        labels.append(np.where(g[tuple(idx.T)] == STEM, STEM_HIT, LEAF_HIT).astype(np.uint8))
    for c in targets.spheres:
        n = max(8, int(4 * math.pi * c[3] ** 2 / spacing**2))
        parts.append(c[:3] + c[3] * _fibonacci_sphere(n))
        labels.append(np.full(n, SPHERE, np.uint8))
    for x, y, zlo, zhi, r in targets.poles:
        z = np.arange(max(zlo, float(terrain.height(x, y))), zhi, spacing)
        a = np.arange(0, 2 * math.pi, max(spacing / r, math.pi / 4))
        zz, aa = np.meshgrid(z, a)
        parts.append(
            np.column_stack([x + r * np.cos(aa.ravel()), y + r * np.sin(aa.ravel()), zz.ravel()])
        )
        labels.append(np.full(zz.size, POLE, np.uint8))
    return np.vstack(parts), np.concatenate(labels)


def _fibonacci_sphere(n: int) -> F64:
    """``n`` nearly uniform unit vectors."""
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = math.pi * (3 - math.sqrt(5)) * k
    rr = np.sqrt(1 - z * z)
    return np.column_stack([rr * np.cos(phi), rr * np.sin(phi), z])
