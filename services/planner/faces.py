"""The exposed cell faces of a field's plots: what the exact visibility kernels
(:mod:`services.planner.exact`) sample."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from common.field import Field

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]


def exposed_faces(field: Field) -> tuple[F64, I64, I64]:
    """The cell faces on the surface of each plot (the ground face only when the plot
    floats above the ground), grouped by plot: ``faces`` (F, 5) = plane, u0, u1, v0,
    v1 with (u, v) the two other axes in cyclic order; ``fint`` (F, 4) = plot, cell,
    axis, outward sign; ``side_start`` (6P + 1,) starts of the faces of side
    ``axis * 2 + (sign > 0)`` of each plot."""
    cb, dims = field.cell_boxes, field.cell_dims
    rows_f: list[F64] = []
    rows_i: list[I64] = []
    counts = np.zeros(6 * field.n_plots, dtype=np.int64)
    for p in range(field.n_plots):
        lo, hi = int(field.cell_offset[p]), int(field.cell_offset[p + 1])
        idx = np.arange(lo, hi)
        loc = np.stack(np.unravel_index(idx - lo, tuple(dims[p])), axis=1)
        for ax in range(3):
            ua, va = (ax + 1) % 3, (ax + 2) % 3
            for sign in (-1, 1):
                if ax == 2 and sign == -1 and field.plot_boxes[p, 2] <= 0.0:
                    continue  # on the ground: its underside cannot be seen
                on = loc[:, ax] == (0 if sign < 0 else dims[p, ax] - 1)
                c = idx[on]
                plane = cb[c, ax + 3] if sign > 0 else cb[c, ax]
                f = np.stack([plane, cb[c, ua], cb[c, ua + 3], cb[c, va], cb[c, va + 3]], 1)
                i = np.stack([np.full(len(c), p), c, np.full(len(c), ax), np.full(len(c), sign)], 1)
                rows_f.append(f)
                rows_i.append(i.astype(np.int64))
                counts[6 * p + ax * 2 + (sign > 0)] += len(c)
    side_start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return np.concatenate(rows_f), np.concatenate(rows_i), side_start
