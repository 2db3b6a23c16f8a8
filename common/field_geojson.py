"""Fields from GeoJSON plot polygons, and WGS84 <-> ``field`` frame conversion.

A plot file is a FeatureCollection of Polygon features in WGS84 (lon, lat), one per plot,
optionally with a ``height`` property (metres) and field-book properties (``plot``,
``entry``, ``rep`` and their aliases: :func:`common.fieldbook.from_properties`). A foreign
member ``"phenorover"`` holds settings (:class:`common.field_geosettings.GeoSettings`);
without ``row_bearing_deg`` the bearing is taken from the longest edge of the first
polygon. Polygons must be axis-aligned rectangles once rotated by the row bearing.

Where a field is on the globe (:func:`placed`): a field that gives its origin is there.
A field that gives none is refused by a real deployment (GNSS would place the robot in
a frame nobody surveyed) and placed at :data:`DEFAULT_ORIGIN` by a simulated one (a
deployment on the sim clock, whose world is the simulator's): the one rule every
service of a deployment applies when it loads the field frame, so all agree.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Literal

import msgspec
import numpy as np
import numpy.typing as npt

from common import fieldbook
from common.arrays import F64
from common.clock import SimClock
from common.field import assemble, field_path, load_field
from common.field_geosettings import GeoSettings
from common.field_model import (
    MAX_PLOTS,
    Field,
    FieldError,
    FieldLayout,
    FieldSettings,
)
from common.geo import FieldFrame


class _Polygon(msgspec.Struct, frozen=True):
    type: Literal["Polygon"]
    coordinates: list[list[list[float]]]


class _Feature(msgspec.Struct, frozen=True):
    type: Literal["Feature"]
    geometry: _Polygon
    properties: dict[str, Any] | None = None


class _Collection(msgspec.Struct, frozen=True, rename={"settings": "phenorover"}):
    type: Literal["FeatureCollection"]
    features: list[_Feature]
    settings: GeoSettings = msgspec.field(default_factory=GeoSettings)


# Where a simulated world puts a field that gives no origin: the origin of the paper's
# ENGR field (common/fields/engr.toml; Iron Horse Farm, Greene County, GA). A real
# place, so simulated GNSS reads as a receiver there would (ordinary latitudes, one
# UTM zone, the same projections the robot uses); (0, 0) would put the field in the
# Gulf of Guinea, on the equator and on the boundary of UTM zones 30 and 31.
DEFAULT_ORIGIN: tuple[float, float] = (33.717028, -83.308083)
ORIGIN_KEYS = ("origin_lat", "origin_lon")


def simulated(clock: object) -> bool:
    """Whether a deployment's world is the simulator's: its clock is the sim clock
    (a manifest's ``clock = "sim"``, or a service's :class:`common.clock.SimClock`)."""
    return clock == "sim" or isinstance(clock, SimClock)


def placed(layout: FieldLayout, source: str | Path, clock: object = None) -> FieldLayout:
    """``layout`` on the globe: as it is when it gives ``origin_lat`` and ``origin_lon``;
    else, in a simulated world (:func:`simulated` of the deployment's ``clock``), at
    :data:`DEFAULT_ORIGIN` (its ``origin_alt`` and ``row_bearing_deg`` kept). Raises
    FieldError naming ``source`` and the missing keys otherwise, and for a field that
    gives only one of the two (a typo, not a choice)."""
    missing = [k for k in ORIGIN_KEYS if getattr(layout, k) is None]
    if not missing:
        return layout
    where = f"{source}: field {layout.name!r}"
    if len(missing) == 1:
        given = ORIGIN_KEYS[1 - ORIGIN_KEYS.index(missing[0])]
        raise FieldError(f"{where}: {given} is set but {missing[0]} is not")
    if not simulated(clock):
        raise FieldError(
            f"{where} has no georeference: origin_lat, origin_lon are not set (a "
            'deployment on the robot needs them; only a simulated one, clock = "sim", '
            "places such a field at a default origin)"
        )
    lat, lon = DEFAULT_ORIGIN
    return msgspec.structs.replace(layout, origin_lat=lat, origin_lon=lon)


def default_origin_note(layout: FieldLayout) -> str:
    """The line that says a field was placed at :data:`DEFAULT_ORIGIN`."""
    lat, lon = DEFAULT_ORIGIN
    ns, ew = "NS"[lat < 0], "EW"[lon < 0]
    return (
        f"field {layout.name!r} has no georeference: placed at the default origin "
        f"{abs(lat):.6f} {ns}, {abs(lon):.6f} {ew} (simulation only; set "
        "origin_lat/origin_lon to survey it)"
    )


def field_frame(layout: FieldLayout) -> FieldFrame:
    """The :class:`common.geo.FieldFrame` of a georeferenced layout; raises ValueError
    when ``origin_lat``/``origin_lon`` are missing (see :func:`placed`)."""
    if layout.origin_lat is None or layout.origin_lon is None:
        raise ValueError(f"field {layout.name!r} has no origin_lat/origin_lon")
    return FieldFrame(
        layout.origin_lat, layout.origin_lon, layout.origin_alt, layout.row_bearing_deg
    )


def load_georeferenced(source: str, clock: object = None) -> tuple[FieldFrame, Field]:
    """The field frame (what every service of a deployment shares) and the field of a
    field file or example, read once. ``clock``: the deployment's (a service's
    ``ctx.clock``), which says whether a field with no origin is placed at
    :data:`DEFAULT_ORIGIN` (:func:`placed`). Raises FieldError, one line naming the
    file, when the field cannot be read or has no place on the globe."""
    layout, fld = load_field(source)
    return field_frame(placed(layout, field_path(source), clock)), fld


def load_frame(source: str, clock: object = None) -> FieldFrame:
    """The field frame of a field file or example (see :func:`load_georeferenced`)."""
    return load_georeferenced(source, clock)[0]


def field_to_wgs84(layout: FieldLayout, xy: F64) -> F64:
    """(N, 2) field x, y metres -> (N, 2) lon, lat degrees (GeoJSON order)."""
    xy = np.asarray(xy, dtype=np.float64)
    lat, lon, _ = field_frame(layout).field_to_wgs84(xy[:, 0], xy[:, 1])
    return np.stack([np.asarray(lon), np.asarray(lat)], axis=-1)


def _groups(centres: F64, tol: float) -> npt.NDArray[np.int64]:
    """Index of the band each centre falls in, bands ordered by increasing centre."""
    order = np.argsort(centres)
    band = np.zeros(len(centres), dtype=np.int64)
    band[order] = np.concatenate([[0], np.cumsum(np.diff(centres[order]) > tol)])
    return band


def _bearing_guess(ring: F64) -> float:
    d = np.diff(ring, axis=0)
    k = int(np.argmax(np.hypot(d[:, 0], d[:, 1])))
    return math.degrees(math.atan2(d[k, 0], d[k, 1])) % 180.0


def field_from_geojson(data: bytes, source: str) -> tuple[FieldLayout, Field]:
    """Decode a plot FeatureCollection; raises FieldError naming ``source``."""
    fc = _decode(data, source)
    s = fc.settings
    rings = _rings(fc, source)
    lon0, lat0 = rings[0][0]
    if not (-180 <= lon0 <= 180 and -90 <= lat0 <= 90):
        raise FieldError(f"{source}: first vertex ({lon0}, {lat0}) is not WGS84 lon, lat")
    # a provisional frame at the first vertex; shifted to the boundary corner below
    frame = FieldFrame(lat0, lon0, 0.0, 0.0)
    enu = [np.stack(frame.wgs84_to_map(r[:, 1], r[:, 0])[:2], axis=-1) for r in rings]
    bearing = s.row_bearing_deg if s.row_bearing_deg is not None else _bearing_guess(enu[0])
    frame = FieldFrame(lat0, lon0, 0.0, bearing)
    boxes = _boxes(fc, enu, frame, bearing, source)
    cx, cy = (boxes[:, 0] + boxes[:, 3]) / 2, (boxes[:, 1] + boxes[:, 4]) / 2
    length = float(np.median(boxes[:, 3] - boxes[:, 0]))
    width = float(np.median(boxes[:, 4] - boxes[:, 1]))
    row, col = _groups(cy, width / 2), _groups(cx, length / 2)
    nrows, ncols = int(row.max()) + 1, int(col.max()) + 1
    if len(set(zip(row.tolist(), col.tolist(), strict=True))) != len(boxes):
        raise FieldError(f"{source}: two plots share a row and column (overlapping plots?)")
    book = fieldbook.from_properties([f.properties for f in fc.features], row, col, source)

    shift = np.array([boxes[:, 0].min() - s.headland_width, boxes[:, 1].min() - s.edge_width])
    boxes[:, [0, 3]] -= shift[0]
    boxes[:, [1, 4]] -= shift[1]
    bounds = np.array(
        [0.0, 0.0, boxes[:, 3].max() + s.headland_width, boxes[:, 4].max() + s.edge_width]
    )
    olat, olon, _ = frame.field_to_wgs84(shift[0], shift[1])
    try:
        layout = FieldLayout(
            **{k: getattr(s, k) for k in FieldSettings.__struct_fields__},
            rows=nrows,
            plots_per_row=ncols,
            plot_length=length,
            plot_width=width,
            plot_height=float(np.median(boxes[:, 5])),
            row_spacing=_gap(boxes, 1, 4, row, nrows),
            alley_width=_gap(boxes, 0, 3, col, ncols),
            headland_width=s.headland_width,
            edge_width=s.edge_width,
            origin_lat=float(olat),
            origin_lon=float(olon),
            row_bearing_deg=float(bearing),
            field_book=book,
        )
        # the constructor does not validate; a round trip through msgspec does
        layout = msgspec.convert(msgspec.to_builtins(layout), FieldLayout)
        field = assemble(layout, boxes, row, col, bounds)
    except (msgspec.ValidationError, FieldError) as exc:
        raise FieldError(f"{source}: {' '.join(str(exc).split())}") from None
    fieldbook.check(layout, field, source)  # plot ids unique (positions are by geometry)
    return layout, field


def _decode(data: bytes, source: str) -> _Collection:
    """The FeatureCollection, of at least one plot and at most ``MAX_PLOTS``."""
    try:
        fc = msgspec.json.decode(data, type=_Collection)
    except msgspec.DecodeError as exc:
        hint = " (every plot must be a Polygon Feature)" if "geometry" in str(exc) else ""
        raise FieldError(f"{source}: {' '.join(str(exc).split())}{hint}") from None
    if not fc.features:
        raise FieldError(f"{source}: the FeatureCollection has no plot polygons")
    if len(fc.features) > MAX_PLOTS:  # before converting any polygon
        raise FieldError(
            f"{source}: {len(fc.features):,} plot polygons, more than the {MAX_PLOTS:,} a "
            "field may have"
        )
    return fc


def _rings(fc: _Collection, source: str) -> list[F64]:
    """Each plot's outer ring (lon, lat)."""
    rings: list[F64] = []
    for i, feat in enumerate(fc.features):
        ring = feat.geometry.coordinates[0] if feat.geometry.coordinates else []
        if len(ring) < 4 or any(len(p) < 2 for p in ring):
            raise FieldError(f"{source}: feature {i} is not a polygon of at least 3 corners")
        rings.append(np.array([p[:2] for p in ring], dtype=np.float64))
    return rings


def _boxes(fc: _Collection, enu: list[F64], frame: FieldFrame, bearing: float, source: str) -> F64:
    """(P, 6) the plots' boxes in the field frame (before its shift to the boundary
    corner): each ring rotated by the rows' bearing must be an axis-aligned rectangle,
    its height its ``height`` property or the settings'."""
    boxes = np.zeros((len(enu), 6))
    for i, (en, feat) in enumerate(zip(enu, fc.features, strict=True)):
        xy = np.stack(frame.map_to_field(en[:, 0], en[:, 1]), axis=-1)
        lo, hi = xy.min(axis=0), xy.max(axis=0)
        area = 0.5 * abs(np.dot(xy[:-1, 0], xy[1:, 1]) - np.dot(xy[1:, 0], xy[:-1, 1]))
        if area < 0.95 * float(np.prod(hi - lo)):
            raise FieldError(
                f"{source}: plot {i} is not an axis-aligned rectangle after rotating by "
                f"row_bearing_deg={bearing:.2f}"
            )
        h = (feat.properties or {}).get("height", fc.settings.plot_height)
        if not isinstance(h, int | float) or h <= 0:
            raise FieldError(f"{source}: plot {i} has height={h!r}, expected metres > 0")
        boxes[i] = [lo[0], lo[1], 0.0, hi[0], hi[1], float(h)]
    return boxes


def _gap(boxes: F64, lo_col: int, hi_col: int, band: npt.NDArray[np.int64], n: int) -> float:
    """The median gap between neighbouring bands (rows or columns) of plots."""
    if n < 2:
        return 1.0
    lo = np.array([boxes[band == k, lo_col].min() for k in range(n)])
    hi = np.array([boxes[band == k, hi_col].max() for k in range(n)])
    return float(np.median(lo[1:] - hi[:-1]))
