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

import dataclasses
import logging
import stat
from pathlib import Path
from typing import Annotated, Literal

import msgspec
import numpy as np
import numpy.typing as npt

log = logging.getLogger(__name__)

# Every float finite by schema (NaN and inf fail a two-sided bound): these configs
# travel nested in plans. Lengths in metres, at most 10 km.
MAX_LENGTH_M = 10_000.0
Pos = Annotated[float, msgspec.Meta(gt=0, le=MAX_LENGTH_M)]
NonNeg = Annotated[float, msgspec.Meta(ge=0, le=MAX_LENGTH_M)]
Altitude = Annotated[float, msgspec.Meta(ge=-1e4, le=1e5)]  # m above the ellipsoid
# Bounds that keep a field description from asking for absurd memory before anything
# can check it (a 10,000-row field used to end in a 17.9 GiB allocation): the largest
# breeding trials have a few thousand plots, and the planner states its own, smaller
# budget (services/planner/budget.py) on top of these.
MAX_ROWS = 1_000  # rows, and plots per row
MAX_PLOTS = 20_000
MAX_CELLS = 5_000_000  # voxel cells of all plots (48 bytes each as boxes)
MAX_EXTENT_M = 5_000.0  # field boundary, along x and along y
MAX_FILE_BYTES = 64 << 20  # a GeoJSON of MAX_PLOTS polygons is about 10 MB
PosInt = Annotated[int, msgspec.Meta(gt=0, le=MAX_ROWS)]
Voxel = Annotated[float, msgspec.Meta(ge=0.01, le=MAX_LENGTH_M)]  # a cell edge (m)
Corner = Literal["bottom-right", "bottom-left", "top-right", "top-left"]
# a registration target as set out on site: x, y (field frame, m) and pole height (m)
Site = tuple[
    Annotated[float, msgspec.Meta(ge=-MAX_LENGTH_M, le=MAX_LENGTH_M)],
    Annotated[float, msgspec.Meta(ge=-MAX_LENGTH_M, le=MAX_LENGTH_M)],
    Annotated[float, msgspec.Meta(gt=0, le=10)],
]

FIELDS_DIR = Path(__file__).with_name("fields")
F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]


class FieldError(ValueError):
    """A field description is wrong; the message is one line naming the source and problem."""


class FieldLayout(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """A regular plot-based breeding field, as a breeder describes it (metres, degrees).

    ``row_spacing`` is the free gap between neighbouring rows of plots (the between-rows
    lanes), ``alley_width`` the free gap between consecutive plots of a row (the cross
    lanes), ``headland_width`` the free strip beyond both row ends and ``edge_width`` the
    free strip beyond the two outer rows (default: ``headland_width``). Plots are cut
    into ``voxel_*`` cells. A lane intersection is a candidate scan location when the
    scanner is at least ``min_scan_distance`` (horizontally) from every plot and the robot
    footprint (``robot_half_length`` x ``robot_half_width``, Husky A200 by default) fits
    there facing along one of the two lanes. ``origin_*`` (WGS84) georeference the
    field frame origin; ``row_bearing_deg`` is the bearing of the field x axis, degrees
    clockwise from north. ``start_corner`` is where tours start and end (the paper's
    Origin is the bottom-right corner). ``targets``: the registration spheres as the
    surveyor set them out, ``[x, y, pole_height]`` each (field frame, m).
    """

    name: str = "field"
    rows: PosInt
    plots_per_row: PosInt
    plot_length: Pos
    plot_width: Pos
    plot_height: Pos
    row_spacing: Pos
    alley_width: Pos
    headland_width: Pos
    edge_width: Pos | None = None
    voxel_x: Voxel = 0.5
    voxel_y: Voxel = 0.5
    voxel_z: Voxel = 0.33
    min_scan_distance: NonNeg = 0.6
    robot_half_length: NonNeg = 0.495
    robot_half_width: NonNeg = 0.335
    origin_lat: Annotated[float, msgspec.Meta(ge=-90, le=90)] | None = None
    origin_lon: Annotated[float, msgspec.Meta(ge=-180, le=180)] | None = None
    origin_alt: Altitude = 0.0
    row_bearing_deg: Annotated[float, msgspec.Meta(ge=-360, le=360)] = 0.0
    start_corner: Corner = "bottom-right"
    targets: tuple[Site, ...] = ()

    @property
    def georeferenced(self) -> bool:
        return self.origin_lat is not None and self.origin_lon is not None


def _default_scanner_height() -> float:
    # imported here: the robot description imports this module for ScannerModel
    from common.robot import default_robot

    return default_robot().scanner.z


class ScannerModel(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """A terrestrial laser scanner: angles in degrees (vertical 0 = horizontal, up
    positive; horizontal counter-clockwise from the field +x axis), ranges and the
    optical-centre height above ground in metres. Defaults: FARO Focus S70 as the
    paper uses it, at the shipped robot's scanner height."""

    vertical_start_deg: Annotated[float, msgspec.Meta(ge=-90, le=90)] = -60.0
    vertical_end_deg: Annotated[float, msgspec.Meta(ge=-90, le=90)] = 90.0
    horizontal_start_deg: Annotated[float, msgspec.Meta(ge=-360, le=360)] = 0.0
    horizontal_end_deg: Annotated[float, msgspec.Meta(ge=-360, le=720)] = 360.0
    step_deg: Annotated[float, msgspec.Meta(gt=0, le=45)] = 0.36
    min_range: NonNeg = 0.6
    max_range: Pos = 70.0
    # the robot description's scanner height (common.robot.scanner_model); by default
    # the shipped robot's
    height: Pos = msgspec.field(default_factory=_default_scanner_height)


@dataclasses.dataclass(frozen=True, eq=False)
class Field:
    """Geometry derived from a layout, in the ``field`` frame (metres).

    Boxes are ``[xmin, ymin, zmin, xmax, ymax, zmax]``. Plot ``p`` is cut into
    ``cell_dims[p]`` = (nx, ny, nz) cells, numbered from ``cell_offset[p]`` in
    x-major order (``offset + (ix * ny + iy) * nz + iz``).
    """

    name: str
    plot_boxes: F64  # (P, 6)
    plot_row: I64  # (P,)
    plot_col: I64  # (P,)
    cell_dims: I64  # (P, 3)
    cell_offset: I64  # (P + 1,)
    cell_boxes: F64  # (C, 6)
    cell_plot: I64  # (C,)
    cross_lanes_x: F64  # (K,) x of every cross lane, headland lanes first and last
    row_lanes_y: F64  # (R,) y of every row-gap lane, field edges first and last
    cand_xy: F64  # (N, 2)
    cand_ids: I64  # (N,)
    cand_row_lane: I64  # (N,)
    cand_cross_lane: I64  # (N,)
    origin_xy: F64  # (2,) tour start, the ``start_corner`` lane intersection
    bounds: F64  # (4,) field boundary [xmin, ymin, xmax, ymax]

    @property
    def n_plots(self) -> int:
        return int(self.plot_boxes.shape[0])

    @property
    def n_cells(self) -> int:
        return int(self.cell_boxes.shape[0])

    @property
    def n_candidates(self) -> int:
        return int(self.cand_xy.shape[0])

    def candidate_index(self, cand_id: int) -> int:
        """Row of ``cand_xy`` holding candidate ``cand_id``; raises ValueError."""
        hit = np.flatnonzero(self.cand_ids == cand_id)
        if hit.size == 0:
            raise ValueError(f"candidate id {cand_id} is not in field {self.name!r}")
        return int(hit[0])


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
    zeros = np.zeros_like(x0, dtype=np.float64)
    boxes = np.stack(
        [
            x0,
            y0,
            zeros,
            x0 + layout.plot_length,
            y0 + layout.plot_width,
            zeros + layout.plot_height,
        ],
        axis=1,
    ).astype(np.float64)
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

    Raises FieldError with one line naming the file and the problem.
    """
    path = field_path(source)
    try:
        # a regular file of sane size: a FIFO or /dev/zero would never end
        st = path.stat()
        if not stat.S_ISREG(st.st_mode):
            raise FieldError(f"{path}: not a regular file")
        if st.st_size > MAX_FILE_BYTES:
            raise FieldError(
                f"{path}: {st.st_size:,} bytes, more than the {MAX_FILE_BYTES:,} a field file "
                "may have"
            )
        data = path.read_bytes()
    except OSError as exc:
        raise FieldError(f"{path}: cannot read: {exc.strerror}") from None
    if path.suffix in (".geojson", ".json"):
        from common.field_geojson import field_from_geojson

        return field_from_geojson(data, str(path))
    try:
        layout = msgspec.toml.decode(data, type=FieldLayout)
    except msgspec.DecodeError as exc:
        raise FieldError(f"{path}: {' '.join(str(exc).split())}") from None
    try:
        return layout, build_field(layout)
    except FieldError as exc:
        raise FieldError(f"{path}: {exc}") from None
