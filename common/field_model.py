"""The field description's types: its layout (what a user writes), the scanner model
the planner plans with, and the geometry derived from a layout (:class:`Field`; built
by :func:`common.field.build_field`). Frames and numbering: :mod:`common.field`."""

from __future__ import annotations

import dataclasses
import datetime
from pathlib import Path
from typing import Annotated, Literal

import msgspec
import numpy as np

from common.arrays import F64, I64
from common.files import read_regular
from common.robot import Robot, default_robot

# Every float finite by schema (NaN and inf fail a two-sided bound): these configs
# travel nested in plans. Lengths in metres, at most 10 km.
MAX_LENGTH_M = 10_000.0
Pos = Annotated[float, msgspec.Meta(gt=0, le=MAX_LENGTH_M)]
NonNeg = Annotated[float, msgspec.Meta(ge=0, le=MAX_LENGTH_M)]
Altitude = Annotated[float, msgspec.Meta(ge=-1e4, le=1e5)]  # m above the ellipsoid
# Bounds that keep a field description from asking for absurd memory before anything
# can check it (a 10,000-row field would end in a 17.9 GiB allocation): the largest
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


class FieldError(ValueError):
    """A field description is wrong; the message is one line naming the source and problem."""


# a plot id or entry name as breeders write them (Breedbase plot names run to ~40 chars)
PlotId = Annotated[str, msgspec.Meta(min_length=1, max_length=64)]
EntryName = Annotated[str, msgspec.Meta(max_length=256)]
BookPath = Annotated[str, msgspec.Meta(min_length=1, max_length=4096)]


class PlotRecord(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """One line of a field book, keyed by plot, as Breedbase and field-book apps keep it."""

    plot: PlotId
    """The plot's id or field-book number, unique in the field."""
    row: PosInt
    """The plot's row: 1 is the bottom row of plots (field row index 0, smallest y)."""
    column: PosInt
    """The plot's place in its row: 1 is the leftmost plot of a row (smallest x)."""
    entry: EntryName = ""
    """The entry (genotype, accession name) sown in the plot; empty: none."""
    rep: Annotated[int, msgspec.Meta(ge=1, le=10_000)] | None = None
    """The replicate or block."""


Book = Annotated[tuple[PlotRecord, ...], msgspec.Meta(max_length=MAX_PLOTS)]


def default_half_length() -> float:
    """Half the length of the shipped robot description's footprint (m;
    ``common/robots/husky.toml``): a field planned for another robot gives its own."""
    return default_robot().footprint.length / 2


def default_half_width() -> float:
    """Half the width of the shipped robot description's footprint (m)."""
    return default_robot().footprint.width / 2


class FieldSettings(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """What a field description says beside its plots, the same in a TOML field
    (:class:`FieldLayout`) and a GeoJSON one
    (:class:`common.field_geosettings.GeoSettings`)."""

    name: str = "field"
    """The field's name."""
    voxel_x: Voxel = 0.5
    """The cells' size along x (m); the paper's cell is 0.5 x 0.5 x 0.33 m."""
    voxel_y: Voxel = 0.5
    """The cells' size along y (m)."""
    voxel_z: Voxel = 0.33
    """The cells' size up (m)."""
    min_scan_distance: NonNeg = 0.6
    """The scanner's least horizontal distance to any plot at a candidate (m; the FARO's
    minimum range)."""
    robot_half_length: NonNeg = msgspec.field(default_factory=default_half_length)
    """Half the length of the footprint that must fit at a candidate (m); by default half
    the shipped robot description's ``[footprint]`` (the Husky A200's)."""
    robot_half_width: NonNeg = msgspec.field(default_factory=default_half_width)
    """Half the width of the footprint that must fit at a candidate (m); by default half
    the shipped robot description's ``[footprint]``."""
    origin_alt: Altitude = 0.0
    """Height of the field frame's origin above the WGS84 ellipsoid (m)."""
    start_corner: Corner = "bottom-right"
    """Where tours start and end; ``bottom-right`` is the paper's Origin."""
    planting_date: datetime.date | None = None
    """The day the trial was sown (TOML local date ``2026-05-01``): the simulator grows a
    trial to a survey date from it, the traits count days after it."""


class FieldLayout(FieldSettings, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """A regular plot-based breeding field, as a breeder describes it (metres, degrees).
    A lane intersection is a candidate scan location when the scanner is at least
    ``min_scan_distance`` (horizontally) from every plot and the robot footprint
    (``robot_half_length`` x ``robot_half_width``) fits there facing along one of the
    two lanes."""

    rows: PosInt
    """Rows of plots (the grid's y)."""
    plots_per_row: PosInt
    """Plots in each row (the grid's x)."""
    plot_length: Pos
    """One plot's box along the row, x (m)."""
    plot_width: Pos
    """One plot's box across the row, y (m)."""
    plot_height: Pos
    """One plot's box up (m): the canopy's height at the stage surveyed."""
    row_spacing: Pos
    """The free gap between neighbouring rows of plots: the between-rows lanes (m)."""
    alley_width: Pos
    """The free gap between consecutive plots of a row: the cross lanes (m)."""
    headland_width: Pos
    """The free strip beyond both row ends (m)."""
    edge_width: Pos | None = None
    """The free strip beyond the two outer rows (m); none: ``headland_width``."""
    origin_lat: Annotated[float, msgspec.Meta(ge=-90, le=90)] | None = None
    """WGS84 latitude of the field frame's origin (deg); without ``origin_lat`` and
    ``origin_lon`` the field has no georeference (docs/configuration.md)."""
    origin_lon: Annotated[float, msgspec.Meta(ge=-180, le=180)] | None = None
    """WGS84 longitude of the field frame's origin (deg)."""
    row_bearing_deg: Annotated[float, msgspec.Meta(ge=-360, le=360)] = 0.0
    """Bearing of the field frame's +x axis (along the rows), degrees clockwise from
    north."""
    targets: tuple[Site, ...] = ()
    """The registration spheres as the surveyor set them out, ``[x, y, pole_height]`` each
    (field frame, m); the simulator stands its spheres there."""
    field_book: BookPath | Book = ()
    """The field book, one :class:`PlotRecord` per plot: ``[[field_book]]`` tables, or the
    path of a CSV file relative to the field file's folder, which
    :func:`common.field.load_field` replaces by its records (:mod:`common.fieldbook`);
    empty: no book, plots numbered from 1 in plot order."""

    @property
    def georeferenced(self) -> bool:
        return self.origin_lat is not None and self.origin_lon is not None


def _default_scanner_height() -> float:
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
    # the robot description's scanner height (scanner_model); by default
    # the shipped robot's
    height: Pos = msgspec.field(default_factory=_default_scanner_height)


def scanner_model(robot: Robot, base: ScannerModel | None = None) -> ScannerModel:
    """The planner's model of ``robot``'s scanner: ``base`` (default: the FARO Focus
    S70 as the paper uses it) with its optical centre at the robot's scanner height."""
    return msgspec.structs.replace(base or ScannerModel(), height=robot.scanner.z)


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


def read_bounded(path: Path, what: str) -> bytes:
    """The bytes of a regular file of at most :data:`MAX_FILE_BYTES`
    (:func:`common.files.read_regular`); FieldError naming ``path``."""
    try:
        return read_regular(path, MAX_FILE_BYTES, what)
    except ValueError as exc:
        raise FieldError(str(exc)) from None
    except OSError as exc:
        raise FieldError(f"{path}: cannot read: {exc.strerror}") from None
