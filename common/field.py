"""The field model shared by the planner and the simulator.

Frame ``field`` (REP-103, metres): x runs along the rows, y across them, z up from the
ground; its origin is the lower-left corner of the field boundary (headlands included),
so every plot is an axis-aligned box. Plots are numbered row by row from the bottom
(``row * plots_per_row + col``).

Lanes: *cross lanes* run along y through the alleys plus one headland lane at each row
end; *row-gap lanes* run along x through the gaps between rows plus one lane outside
each outer row (the field edges). Candidate scan locations are the lane intersections
that pass the clearance rules; their ids are ``r * n_cross + c + 1`` with ``r`` the
row-gap lane from the bottom and ``c`` the cross lane from the left (both from 0), the
numbering that reproduces the paper's ENGR route (``7r + c + 1`` there).
"""

from __future__ import annotations

import logging
from pathlib import Path

import msgspec
import numpy as np
import numpy.typing as npt

from common import fieldbook
from common.arrays import F64, I64

# the types live in common.field_model; the field's users take them from here
from common.field_model import (
    FIELDS_DIR,
    MAX_CELLS,
    MAX_EXTENT_M,
    MAX_PLOTS,
    Field,
    FieldError,
    FieldLayout,
    ScannerModel,
    read_bounded,
)

__all__ = [
    "FIELDS_DIR",
    "Field",
    "FieldError",
    "FieldLayout",
    "ScannerModel",
    "assemble",
    "build_field",
    "cell_dims",
    "check_size",
    "example_names",
    "field_path",
    "load_field",
]

log = logging.getLogger(__name__)


def _cells_along(extent: float, voxel: float) -> int:
    # Round to the nearest count so a 3 x 1 x 1 plot gets 6 x 2 x 3 = 36 cells as in the
    # paper (ceil would give 4 layers for 1 m / 0.33 m).
    return max(1, round(extent / voxel))


def cell_dims(layout: FieldLayout, boxes: F64) -> I64:
    """Cells (nx, ny, nz) of each plot box (P, 6); raises FieldError when all plots
    together would have more than :data:`MAX_CELLS` (checked before any cell exists)."""
    vox = (layout.voxel_x, layout.voxel_y, layout.voxel_z)
    ext = boxes[:, 3:6] - boxes[:, 0:3]
    # counted in floats first: tiny voxels on huge plots overflow int64
    approx = np.maximum(1.0, np.round(ext / np.array(vox)))
    total = float(np.prod(approx, axis=1).sum())
    if total > MAX_CELLS:
        raise FieldError(
            f"field {layout.name!r}: {total:,.0f} voxel cells (voxel_x/y/z = "
            f"{vox[0]:g} x {vox[1]:g} x {vox[2]:g} m), more than the {MAX_CELLS:,} a field "
            "may have; use larger voxels or fewer plots"
        )
    dims = np.empty((len(boxes), 3), dtype=np.int64)
    for a in range(3):
        dims[:, a] = [_cells_along(float(e), vox[a]) for e in ext[:, a]]
    return dims


def check_size(name: str, boxes: F64, bounds: F64) -> None:
    """Raise FieldError when a field has more than :data:`MAX_PLOTS` plots or is more
    than :data:`MAX_EXTENT_M` across."""
    if len(boxes) > MAX_PLOTS:
        raise FieldError(
            f"field {name!r}: {len(boxes):,} plots, more than the {MAX_PLOTS:,} a field may have"
        )
    size = bounds[2:4] - bounds[0:2]
    if not np.all(np.isfinite(size)) or size.max() > MAX_EXTENT_M:
        raise FieldError(
            f"field {name!r}: {size[0]:,.1f} m x {size[1]:,.1f} m, more than "
            f"{MAX_EXTENT_M:,.0f} m across"
        )


def _lanes_between(lo: F64, hi: F64, margin_lo: float, margin_hi: float) -> F64:
    """Lane centres in the gaps between consecutive [lo, hi] bands plus one lane
    ``margin`` outside each outer band."""
    mids = (hi[:-1] + lo[1:]) / 2.0
    return np.concatenate([[lo[0] - margin_lo], mids, [hi[-1] + margin_hi]])


def assemble(layout: FieldLayout, boxes: F64, row: I64, col: I64, bounds: F64) -> Field:
    """Build a :class:`Field` from plot boxes and their row/column indices.

    Shared by :func:`build_field` (regular layouts) and the GeoJSON loader (measured
    plots). Raises FieldError when rows or columns overlap.
    """
    check_size(layout.name, boxes, bounds)
    nrows, ncols = int(row.max()) + 1, int(col.max()) + 1
    row_lo = np.array([boxes[row == r, 1].min() for r in range(nrows)])
    row_hi = np.array([boxes[row == r, 4].max() for r in range(nrows)])
    col_lo = np.array([boxes[col == c, 0].min() for c in range(ncols)])
    col_hi = np.array([boxes[col == c, 3].max() for c in range(ncols)])
    if np.any(row_lo[1:] <= row_hi[:-1]) or np.any(col_lo[1:] <= col_hi[:-1]):
        raise FieldError(f"field {layout.name!r}: rows or columns of plots overlap")
    # Outer lanes sit half an inner lane outside the outer plots, so the lane grid keeps
    # one pitch and the scanner the same clearance there as at inner intersections.
    xs = _lanes_between(col_lo, col_hi, layout.alley_width / 2, layout.alley_width / 2)
    ys = _lanes_between(row_lo, row_hi, layout.row_spacing / 2, layout.row_spacing / 2)

    dims = cell_dims(layout, boxes)
    counts = dims.prod(axis=1)
    offset = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    cell_plot = np.repeat(np.arange(len(boxes), dtype=np.int64), counts)
    cells = np.empty((int(offset[-1]), 6))
    for p, (nx, ny, nz) in enumerate(dims):
        lo, hi = boxes[p, :3], boxes[p, 3:]
        size = (hi - lo) / np.array([nx, ny, nz])
        ix, iy, iz = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
        idx = np.stack([ix.ravel(), iy.ravel(), iz.ravel()], axis=1)
        cmin = lo + idx * size
        cells[offset[p] : offset[p + 1]] = np.hstack([cmin, cmin + size])

    gx, gy = np.meshgrid(xs, ys)  # (R, K): row-gap lane r, cross lane c
    r_idx, c_idx = np.meshgrid(np.arange(len(ys)), np.arange(len(xs)), indexing="ij")
    xy = np.stack([gx.ravel(), gy.ravel()], axis=1)
    ok = _clear(layout, xy, boxes)
    ids = (r_idx * len(xs) + c_idx + 1).ravel()
    if not ok.all():
        log.info("field %s: %d lane intersections fail clearance", layout.name, (~ok).sum())
    corner = {
        "bottom-left": (xs[0], ys[0]),
        "bottom-right": (xs[-1], ys[0]),
        "top-left": (xs[0], ys[-1]),
        "top-right": (xs[-1], ys[-1]),
    }[layout.start_corner]
    return Field(
        name=layout.name,
        plot_boxes=boxes,
        plot_row=row.astype(np.int64),
        plot_col=col.astype(np.int64),
        cell_dims=dims,
        cell_offset=offset,
        cell_boxes=cells,
        cell_plot=cell_plot,
        cross_lanes_x=xs,
        row_lanes_y=ys,
        cand_xy=xy[ok],
        cand_ids=ids[ok].astype(np.int64),
        cand_row_lane=r_idx.ravel()[ok].astype(np.int64),
        cand_cross_lane=c_idx.ravel()[ok].astype(np.int64),
        origin_xy=np.array(corner, dtype=np.float64),
        bounds=bounds,
    )


def _clear(layout: FieldLayout, xy: F64, boxes: F64, chunk: int = 256) -> npt.NDArray[np.bool_]:
    """Clearance rules of the paper (section "Environment modeling").

    Only plots nearer than ``reach`` along both axes can fail a rule, so candidates are
    tested in spatially compact chunks against the plots near each chunk: memory stays
    at chunk x nearby plots instead of candidates x plots (1.6 GB for 100 x 100 plots).
    """
    hl, hw = layout.robot_half_length, layout.robot_half_width
    reach = max(layout.min_scan_distance, hl, hw)
    ok = np.ones(len(xy), dtype=bool)
    order = np.lexsort((xy[:, 0], xy[:, 1]))
    for s in range(0, len(order), chunk):
        idx = order[s : s + chunk]
        p = xy[idx]
        lo_c, hi_c = p.min(axis=0) - reach, p.max(axis=0) + reach
        near = np.all((boxes[:, 0:2] < hi_c) & (boxes[:, 3:5] > lo_c), axis=1)
        if not near.any():
            continue
        lo, hi = boxes[None, near, 0:2], boxes[None, near, 3:5]
        gap = np.maximum(np.maximum(lo - p[:, None, :], p[:, None, :] - hi), 0.0)
        far = np.hypot(gap[..., 0], gap[..., 1]).min(axis=1) >= layout.min_scan_distance
        fits = np.zeros(len(idx), dtype=bool)
        for ax, ay in ((hl, hw), (hw, hl)):  # facing along x, then along y
            fits |= ~((gap[..., 0] < ax) & (gap[..., 1] < ay)).any(axis=1)
        ok[idx] = far & fits
    return ok


def build_field(layout: FieldLayout) -> Field:
    """The regular field of ``layout``; raises FieldError when headland or edge strips
    are too narrow to hold the outer lanes."""
    edge = layout.edge_width if layout.edge_width is not None else layout.headland_width
    if layout.headland_width < layout.alley_width / 2:
        raise FieldError(
            f"field {layout.name!r}: headland_width={layout.headland_width} is less than "
            f"half the alley_width={layout.alley_width}, so the headland lane does not fit"
        )
    if edge < layout.row_spacing / 2:
        raise FieldError(
            f"field {layout.name!r}: edge_width={edge} is less than half the "
            f"row_spacing={layout.row_spacing}, so the edge lane does not fit"
        )
    n = layout.rows * layout.plots_per_row
    if n > MAX_PLOTS:  # before allocating anything per plot
        raise FieldError(
            f"field {layout.name!r}: rows x plots_per_row = {layout.rows} x "
            f"{layout.plots_per_row} = {n:,} plots, more than the {MAX_PLOTS:,} a field may have"
        )
    px = layout.plot_length + layout.alley_width
    py = layout.plot_width + layout.row_spacing
    row, col = np.divmod(np.arange(layout.rows * layout.plots_per_row), layout.plots_per_row)
    x0 = layout.headland_width + col * px
    y0 = edge + row * py
    lo = np.stack([x0, y0, np.zeros_like(x0)], axis=1).astype(np.float64)
    size = np.array([layout.plot_length, layout.plot_width, layout.plot_height])
    boxes = np.hstack([lo, lo + size])
    bounds = np.array(
        [
            0.0,
            0.0,
            x0.max() + layout.plot_length + layout.headland_width,
            y0.max() + layout.plot_width + edge,
        ]
    )
    return assemble(layout, boxes, row.astype(np.int64), col.astype(np.int64), bounds)


def example_names() -> list[str]:
    """Names of the fields shipped in ``common/fields``."""
    return sorted(p.stem for p in FIELDS_DIR.iterdir() if p.suffix in (".toml", ".geojson"))


def field_path(source: str | Path) -> Path:
    """The file a field source names: the path itself, or for a bare name (no folder,
    no suffix) that is not a file here, the shipped example ``common/fields/NAME.*``.
    Raises FieldError when there is no such example."""
    path = Path(source)
    if not path.exists() and path.suffix == "" and "/" not in str(source):
        for ext in (".toml", ".geojson"):
            if (FIELDS_DIR / f"{source}{ext}").exists():
                return FIELDS_DIR / f"{source}{ext}"
        raise FieldError(
            f"{source}: no such field file or example (examples: {', '.join(example_names())})"
        )
    return path


def load_field(source: str | Path) -> tuple[FieldLayout, Field]:
    """Read a field from a TOML layout, a GeoJSON FeatureCollection of plot polygons
    (see :mod:`common.field_geojson`), or a shipped example name (``engr``, ``spl``).
    A TOML's CSV ``field_book`` is read from beside it; a book must match the plots
    (:mod:`common.fieldbook`).

    Raises FieldError with one line naming the file and the problem.
    """
    path = field_path(source)
    data = read_bounded(path, "a field file")
    if path.suffix in (".geojson", ".json"):
        from common.field_geojson import field_from_geojson

        return field_from_geojson(data, str(path))
    try:
        layout = msgspec.toml.decode(data, type=FieldLayout)
    except msgspec.DecodeError as exc:
        raise FieldError(f"{path}: {' '.join(str(exc).split())}") from None
    book = fieldbook.label(layout, path.parent)  # before resolve reads a CSV book
    layout = fieldbook.resolve(layout, path.parent, str(path))
    try:
        fld = build_field(layout)
    except FieldError as exc:
        raise FieldError(f"{path}: {exc}") from None
    fieldbook.check(layout, fld, str(path), book)
    return layout, fld
