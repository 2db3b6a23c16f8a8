"""Exact (resolution-free) visibility kernels.

For each candidate and each exposed cell face, ``samples x samples`` points of the face
are tested: a point counts when the straight line from the optical centre meets nothing
before it, within the range limits and the field of view.

When every plot stands on the ground and reaches the optical centre (plants taller than
the scanner, the paper's case), occlusion is planar: a line of sight is blocked exactly
when its ground projection crosses a plot at least as tall as both ends. The kernels
then skip plots and sides that one box hides (:mod:`services.planner.occlusion`) and
decide a whole column of sample points with one horizontal ray; the table is identical
to testing every point in 3D (a test checks that), at a fraction of the rays.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
import numpy.typing as npt

from common.arrays import F64, I64
from services.planner.occlusion import plot_hidden, side_hidden
from services.planner.raycast import GridArgs, Table, cell_of, first_hit, record

# the scanner's limits as the kernels take them: (min range, max range, vertical start
# and end, horizontal start, horizontal span), metres and degrees
Limits = tuple[float, float, float, float, float, float]


@nb.njit(cache=True, error_model="numpy")
def _sample(
    a: int,
    o: F64,
    p: int,
    f: int,
    ax: int,
    su: int,
    sv: int,
    samples: int,
    lim: Limits,
    known: int,
    faces: F64,
    fint: I64,
    grid: GridArgs,
    out: Table,
) -> int:
    """Test sample (su, sv) of face f from origin row a; ``known`` = 1 when the line of
    sight is already known to be clear (planar case), else a ray is cast. Returns the
    number of rays cast (0 or 1)."""
    rmin, rmax, vmin, vmax, hmin, hspan = lim
    boxes = grid[0]
    dims, offset = out[0], out[1]
    c0 = faces[f, 0]
    uu = faces[f, 1] + (su + 0.5) / samples * (faces[f, 2] - faces[f, 1])
    vv = faces[f, 3] + (sv + 0.5) / samples * (faces[f, 4] - faces[f, 3])
    # (u, v) are the two other axes in cyclic order after ``ax``
    if ax == 0:
        qx, qy, qz = c0, uu, vv
    elif ax == 1:
        qx, qy, qz = vv, c0, uu
    else:
        qx, qy, qz = uu, vv, c0
    dx, dy, dz = qx - o[0], qy - o[1], qz - o[2]
    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
    if dist < rmin or dist > rmax:
        return 0
    el = math.degrees(math.asin(dz / dist))
    if el < vmin or el > vmax:
        return 0
    if hspan < 360.0:
        az = (math.degrees(math.atan2(dy, dx)) - hmin) % 360.0
        if az > hspan:
            return 0
    cell = fint[f, 1]
    if known == 0:
        dx, dy, dz = dx / dist, dy / dist, dz / dist
        hp, t = first_hit(
            o[0],
            o[1],
            o[2],
            dx,
            dy,
            dz,
            dist + 1e-6,
            grid,
        )
        if hp != p:
            return 1
        hc = cell_of(hp, o[0] + t * dx, o[1] + t * dy, o[2] + t * dz, boxes, dims, offset)
        if hc != cell:
            return 1
    record(a, p, cell, dist, out)
    return 1 - known


@nb.njit(cache=True, error_model="numpy")
def _planar_side(
    a: int,
    o: F64,
    p: int,
    ax: int,
    plane: float,
    s0: int,
    s1: int,
    samples: int,
    lim: Limits,
    faces: F64,
    fint: I64,
    grid: GridArgs,
    out: Table,
) -> int:
    """A vertical side under planar occlusion: one horizontal ray per column of sample
    points decides the whole column (every layer, every height sample): clear when it
    reaches plot p first, hidden when a box at least as tall as p is in the way, and
    tested sample by sample in 3D otherwise. Faces of a side come column by column,
    ``nz`` layers each. Returns the rays cast."""
    rmin, rmax, vmin, vmax, hmin, hspan = lim
    boxes = grid[0]
    nz = out[0][p, 2]
    rays = 0
    for col in range((s1 - s0) // nz):
        f0 = s0 + col * nz
        for sh in range(samples):
            if ax == 0:  # u = y is horizontal, v = z
                h = faces[f0, 1] + (sh + 0.5) / samples * (faces[f0, 2] - faces[f0, 1])
                ex, ey = plane, h
            else:  # u = z, v = x is horizontal
                h = faces[f0, 3] + (sh + 0.5) / samples * (faces[f0, 4] - faces[f0, 3])
                ex, ey = h, plane
            dx, dy = ex - o[0], ey - o[1]
            d = math.sqrt(dx * dx + dy * dy)
            rays += 1
            b, _ = first_hit(
                o[0],
                o[1],
                o[2],
                dx / d,
                dy / d,
                0.0,
                d + 1e-6,
                grid,
            )
            if b >= 0 and b != p and boxes[b, 5] >= boxes[p, 5]:
                continue  # a box as tall as p hides the whole column
            if b != p:
                for f in range(f0, f0 + nz):
                    for sv in range(samples):
                        su, sw = (sh, sv) if ax == 0 else (sv, sh)
                        rays += _sample(
                            a,
                            o,
                            p,
                            f,
                            ax,
                            su,
                            sw,
                            samples,
                            lim,
                            0,
                            faces,
                            fint,
                            grid,
                            out,
                        )
                continue
            # clear line of sight at every height: only the range and field-of-view
            # limits remain (kept inline: this is the hot loop)
            az_ok = True
            if hspan < 360.0:
                az_ok = (math.degrees(math.atan2(dy, dx)) - hmin) % 360.0 <= hspan
            if not az_ok:
                continue
            d2 = d * d
            for f in range(f0, f0 + nz):
                # the vertical axis is v for x sides and u for y sides
                z0, z1 = (faces[f, 3], faces[f, 4]) if ax == 0 else (faces[f, 1], faces[f, 2])
                cell = fint[f, 1]
                for sv in range(samples):
                    dz = z0 + (sv + 0.5) / samples * (z1 - z0) - o[2]
                    dist = math.sqrt(d2 + dz * dz)
                    if dist < rmin or dist > rmax:
                        continue
                    el = math.degrees(math.atan2(dz, d))
                    if el < vmin or el > vmax:
                        continue
                    record(a, p, cell, dist, out)
    return rays


@nb.njit(parallel=True, cache=True, error_model="numpy")
def exact_kernel(
    origins: F64,
    lim: Limits,
    samples: int,
    cull: bool,
    faces: F64,
    fint: I64,
    side_start: I64,
    grid: GridArgs,
    out: Table,
) -> npt.NDArray[np.int64]:
    # faces[f] = [plane, u0, u1, v0, v1]; fint[f] = [plot, cell, axis, sign]; the faces of
    # side s (= axis * 2 + (sign > 0)) of plot p are side_start[6p + s] .. [6p + s + 1]
    boxes = grid[0]
    base = out[2]
    k = origins.shape[0]
    nrays = np.zeros(k, dtype=np.int64)
    for a in nb.prange(k):
        o = origins[a]
        last = -1
        for p in range(boxes.shape[0]):
            if base[a, p] < 0:
                continue  # beyond the scanner's range
            if cull:
                blocker = plot_hidden(o, p, last, grid)
                if blocker >= 0:
                    last = blocker
                    continue
            for side in range(6):
                s0, s1 = side_start[6 * p + side], side_start[6 * p + side + 1]
                if s0 == s1:
                    continue
                ax = side // 2
                sg = 1 if side % 2 else -1
                plane = boxes[p, ax + 3] if sg > 0 else boxes[p, ax]
                if sg * (o[ax] - plane) <= 1e-9:
                    continue  # the side looks away from the scanner
                if cull and ax < 2 and side_hidden(o, p, ax, plane, grid):
                    continue
                if cull and ax < 2:
                    nrays[a] += _planar_side(
                        a,
                        o,
                        p,
                        ax,
                        plane,
                        s0,
                        s1,
                        samples,
                        lim,
                        faces,
                        fint,
                        grid,
                        out,
                    )
                    continue
                for f in range(s0, s1):
                    for su in range(samples):
                        for sv in range(samples):
                            nrays[a] += _sample(
                                a,
                                o,
                                p,
                                f,
                                ax,
                                su,
                                sv,
                                samples,
                                lim,
                                0,
                                faces,
                                fint,
                                grid,
                                out,
                            )
    return nrays
