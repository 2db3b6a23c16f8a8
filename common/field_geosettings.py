"""What a GeoJSON field's polygons cannot carry: the settings in its FeatureCollection's
foreign member ``"phenorover"`` (:mod:`common.field_geojson` reads the polygons)."""

from __future__ import annotations

from typing import Annotated

import msgspec

from common.field_model import FieldSettings, Pos


class GeoSettings(FieldSettings, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """A GeoJSON field's settings: those of every field (:class:`FieldSettings`, as a
    TOML field has them) and the few a TOML field states otherwise. The grid, plot
    sizes, lanes and origin come from the polygons."""

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
