"""Planar occlusion culling for the exact visibility kernels.

When every plot stands on the ground and reaches the scanner's optical centre (plants
taller than the scanner, the paper's case), a line of sight is blocked exactly when its
ground projection crosses a plot at least as tall as both ends. These tests then decide
that one (convex) box hides a whole plot or a whole side, so the kernels
(:mod:`services.planner.exact`) skip it without casting a ray per sample.
"""

from __future__ import annotations

import math

import numba as nb

from common.arrays import F64
from services.planner.raycast import GridArgs, _slab, first_hit


@nb.njit(cache=True, error_model="numpy")
def _seg_hits(b: int, ox: float, oy: float, cx: float, cy: float, boxes: F64) -> bool:
    """Whether the segment from o to just short of c crosses box b's footprint."""
    dx, dy = cx - ox, cy - oy
    a0, a1 = _slab(boxes[b, 0], boxes[b, 3], ox, 1.0 / dx, dx)
    b0, b1 = _slab(boxes[b, 1], boxes[b, 4], oy, 1.0 / dy, dy)
    return max(a0, b0, 0.0) <= min(a1, b1, 1.0 - 1e-9)


@nb.njit(cache=True, error_model="numpy")
def _one_box_hides(
    o: F64, p: int, ex0: float, ey0: float, ex1: float, ey1: float, grid: GridArgs
) -> int:
    """The box that the horizontal rays from o to (ex0, ey0) and to (ex1, ey1) both hit
    first, when it is at least as tall as plot p; else -1. Under planar occlusion that
    (convex) box cuts every line of sight between the two rays, over p's whole height."""
    boxes = grid[0]
    hit = -1
    for e in range(2):
        ex, ey = (ex0, ey0) if e == 0 else (ex1, ey1)
        dx, dy = ex - o[0], ey - o[1]
        d = math.sqrt(dx * dx + dy * dy)
        if d < 1e-9:
            return -1
        b, _ = first_hit(o[0], o[1], o[2], dx / d, dy / d, 0.0, d * (1.0 - 1e-9) - 1e-7, grid)
        if b < 0 or b == p or (e == 1 and b != hit) or boxes[b, 5] < boxes[p, 5]:
            return -1
        hit = b
    return hit


@nb.njit(cache=True, error_model="numpy")
def plot_hidden(
    o: F64,
    p: int,
    last: int,
    grid: GridArgs,
) -> int:
    """Box that hides all of plot p under planar occlusion, or -1.

    The lines of sight to the two silhouette corners of p's footprint must both cross
    the same box B, at least as tall as p; B, convex and disjoint from p, then cuts the
    whole wedge in front of p. ``last`` (the previous blocker) is tried first without
    casting, since far plots tend to hide behind the same near one.
    """
    boxes = grid[0]
    cx = 0.5 * (boxes[p, 0] + boxes[p, 3]) - o[0]
    cy = 0.5 * (boxes[p, 1] + boxes[p, 4]) - o[1]
    lo, hi = math.inf, -math.inf
    k_lo, k_hi = 0, 0
    for k in range(4):
        vx = boxes[p, 0 if k < 2 else 3] - o[0]
        vy = boxes[p, 1 if k % 2 == 0 else 4] - o[1]
        ang = math.atan2(cx * vy - cy * vx, cx * vx + cy * vy)
        if ang < lo:
            lo, k_lo = ang, k
        if ang > hi:
            hi, k_hi = ang, k
    if hi - lo >= math.pi:
        return -1  # o is inside or on the footprint
    ex = (boxes[p, 0 if k_lo < 2 else 3], boxes[p, 0 if k_hi < 2 else 3])
    ey = (boxes[p, 1 if k_lo % 2 == 0 else 4], boxes[p, 1 if k_hi % 2 == 0 else 4])
    if (
        last >= 0
        and last != p
        and boxes[last, 5] >= boxes[p, 5]
        and _seg_hits(last, o[0], o[1], ex[0], ey[0], boxes)
        and _seg_hits(last, o[0], o[1], ex[1], ey[1], boxes)
    ):
        return last
    return _one_box_hides(o, p, ex[0], ey[0], ex[1], ey[1], grid)


@nb.njit(cache=True, error_model="numpy")
def side_hidden(
    o: F64,
    p: int,
    ax: int,
    plane: float,
    grid: GridArgs,
) -> bool:
    """Whether one box hides the whole vertical side ``ax``/``plane`` of plot ``p``.

    Valid only when every box stands on the ground and reaches the scanner height: then
    occlusion is planar, and if the horizontal rays to both ends of the side hit the same
    (convex) box B first, B cuts every line of sight to the side; B must also be at
    least as tall as the plot so lines of sight to its top are cut too.
    """
    boxes = grid[0]
    if ax == 0:
        ex0, ey0, ex1, ey1 = plane, boxes[p, 1], plane, boxes[p, 4]
    else:
        ex0, ey0, ex1, ey1 = boxes[p, 0], plane, boxes[p, 3], plane
    return _one_box_hides(o, p, ex0, ey0, ex1, ey1, grid) >= 0
