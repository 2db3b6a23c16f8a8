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


class FieldError(ValueError):
    """A field description is wrong; the message is one line naming the source and problem."""


# a plot id or entry name as breeders write them (Breedbase plot names run to ~40 chars)
PlotId = Annotated[str, msgspec.Meta(min_length=1, max_length=64)]
EntryName = Annotated[str, msgspec.Meta(max_length=256)]
BookPath = Annotated[str, msgspec.Meta(min_length=1, max_length=4096)]


class PlotRecord(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """One line of a field book (Breedbase convention): row 1 is the bottom row of plots
    (field row index 0, smallest y), column 1 the leftmost plot of a row (smallest x)."""

    plot: PlotId  # plot id / field-book number, unique in the field
    row: PosInt
    column: PosInt
    entry: EntryName = ""  # entry / genotype / accession name ("" = none)
    rep: Annotated[int, msgspec.Meta(ge=1, le=10_000)] | None = None  # replicate or block


Book = Annotated[tuple[PlotRecord, ...], msgspec.Meta(max_length=MAX_PLOTS)]


def default_half_length() -> float:
    """Half the length of the robot description's footprint (m)."""
    return default_robot().footprint.length / 2


def default_half_width() -> float:
    """Half the width of the robot description's footprint (m)."""
    return default_robot().footprint.width / 2


class FieldLayout(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """A regular plot-based breeding field, as a breeder describes it (metres, degrees).

    ``row_spacing`` is the free gap between neighbouring rows of plots (the between-rows
    lanes), ``alley_width`` the free gap between consecutive plots of a row (the cross
    lanes), ``headland_width`` the free strip beyond both row ends and ``edge_width`` the
    free strip beyond the two outer rows (default: ``headland_width``). Plots are cut
    into ``voxel_*`` cells. A lane intersection is a candidate scan location when the
    scanner is at least ``min_scan_distance`` (horizontally) from every plot and the robot
    footprint (``robot_half_length`` x ``robot_half_width``; by default half the robot
    description's footprint, the paper's Husky A200) fits
    there facing along one of the two lanes. ``origin_*`` (WGS84) georeference the
    field frame origin; ``row_bearing_deg`` is the bearing of the field x axis, degrees
    clockwise from north. ``start_corner`` is where tours start and end (the paper's
    Origin is the bottom-right corner). ``targets``: the registration spheres as the
    surveyor set them out, ``[x, y, pole_height]`` each (field frame, m).

    ``field_book``: one :class:`PlotRecord` per plot (plot id, row, column, entry, rep),
    in TOML an array of tables ``[[field_book]]``, or a string: the path of a CSV file
    relative to the TOML file's folder, which :func:`common.field.load_field` replaces
    by its records (see :mod:`common.fieldbook`); empty: no book. ``planting_date``:
    the day the trial was sown (TOML local date ``2026-05-01``); the simulator grows
    plants by days after planting.
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
    robot_half_length: NonNeg = msgspec.field(default_factory=default_half_length)
    robot_half_width: NonNeg = msgspec.field(default_factory=default_half_width)
    origin_lat: Annotated[float, msgspec.Meta(ge=-90, le=90)] | None = None
    origin_lon: Annotated[float, msgspec.Meta(ge=-180, le=180)] | None = None
    origin_alt: Altitude = 0.0
    row_bearing_deg: Annotated[float, msgspec.Meta(ge=-360, le=360)] = 0.0
    start_corner: Corner = "bottom-right"
    targets: tuple[Site, ...] = ()
    field_book: BookPath | Book = ()
    planting_date: datetime.date | None = None

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
