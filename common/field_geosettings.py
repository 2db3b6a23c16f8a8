"""What a GeoJSON field's polygons cannot carry: the settings in its FeatureCollection's
foreign member ``"phenorover"`` (:mod:`common.field_geojson` reads the polygons)."""

from __future__ import annotations

import datetime
from typing import Annotated

import msgspec

from common.field_model import (
    Altitude,
    Corner,
    NonNeg,
    Pos,
    Voxel,
    default_half_length,
    default_half_width,
)


class GeoSettings(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """A GeoJSON field's settings; the keys a TOML field shares mean the same
    (:class:`common.field_model.FieldLayout`). The grid, plot sizes, lanes and origin
    come from the polygons."""

    name: str = "field"
    """The field's name."""
    row_bearing_deg: Annotated[float, msgspec.Meta(ge=-360, le=360)] | None = None
    """Bearing of the rows (the field frame's +x), degrees clockwise from north; none: that
    of the first polygon's longest edge. Polygons must be rectangles aligned with it."""
    plot_height: Pos = 1.0
    """A plot's height where its polygon has no ``height`` property (m)."""
    headland_width: Pos = 2.0
    """The free strip beyond both row ends (m); the field frame's origin is this far
    before the first plots."""
    edge_width: Pos = 1.5
    """The free strip beyond the two outer rows (m)."""
    voxel_x: Voxel = 0.5
    """The cells' size along x (m)."""
    voxel_y: Voxel = 0.5
    """The cells' size along y (m)."""
    voxel_z: Voxel = 0.33
    """The cells' size up (m)."""
    min_scan_distance: NonNeg = 0.6
    """The scanner's least horizontal distance to any plot at a candidate (m)."""
    robot_half_length: NonNeg = msgspec.field(default_factory=default_half_length)
    """Half the length of the footprint that must fit at a candidate (m); by default half
    the shipped robot description's ``[footprint]``."""
    robot_half_width: NonNeg = msgspec.field(default_factory=default_half_width)
    """Half the width of the footprint that must fit at a candidate (m); by default half
    the shipped robot description's ``[footprint]``."""
    origin_alt: Altitude = 0.0
    """Height of the field frame's origin above the WGS84 ellipsoid (m)."""
    start_corner: Corner = "bottom-right"
    """Where tours start and end; ``bottom-right`` is the paper's Origin."""
    planting_date: datetime.date | None = None
    """The day the trial was sown (``"2026-05-01"``)."""
