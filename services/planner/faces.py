"""The exposed cell faces of a field's plots: what the exact visibility kernels
(:mod:`services.planner.exact`) sample."""

from __future__ import annotations

import numpy as np

from common.arrays import F64, I64
from common.field import Field


def exposed_faces(field: Field) -> tuple[F64, I64, I64]:
    """The cell faces on the surface of each plot (the ground face only when the plot
    floats above the ground), grouped by plot: ``faces`` (F, 5) = plane, u0, u1, v0,
    v1 with (u, v) the two other axes in cyclic order; ``fint`` (F, 4) = plot, cell,
    axis, outward sign; ``side_start`` (6P + 1,) starts of the faces of side
    ``axis * 2 + (sign > 0)`` of each plot, the faces of a side by cell."""
    cb, cp = field.cell_boxes, field.cell_plot
    dims = field.cell_dims[cp]  # (C, 3) of each cell's plot
    local = np.arange(field.n_cells) - field.cell_offset[cp]
    loc = np.stack(
        [
            local // (dims[:, 1] * dims[:, 2]),
            (local // dims[:, 2]) % dims[:, 1],
            local % dims[:, 2],
        ],
        axis=1,
    )
    on_ground = field.plot_boxes[cp, 2] <= 0.0
    cells: list[I64] = []
    sides: list[I64] = []
    for s in range(6):
        axis, outward = divmod(s, 2)
        on = loc[:, axis] == (dims[:, axis] - 1 if outward else 0)
        if axis == 2 and not outward:
            on &= ~on_ground  # on the ground: its underside cannot be seen
        cells.append(np.flatnonzero(on))
        sides.append(np.full(int(on.sum()), s, dtype=np.int64))
    c, side = np.concatenate(cells), np.concatenate(sides)
    order = np.lexsort((c, side, cp[c]))
    c, side = c[order], side[order]
    ax, sign = side // 2, np.where(side % 2 == 1, 1, -1)
    plane = cb[c, ax + 3 * (sign > 0)]
    ua, va = (ax + 1) % 3, (ax + 2) % 3
    faces = np.stack([plane, cb[c, ua], cb[c, ua + 3], cb[c, va], cb[c, va + 3]], axis=1)
    fint = np.stack([cp[c], c, ax, sign], axis=1).astype(np.int64)
    counts = np.bincount(cp[c] * 6 + side, minlength=6 * field.n_plots)
    side_start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return faces, fint, side_start
