"""Frames and conversions: WGS84 <-> map (local ENU) <-> field, UTM, SE(2)/SE(3).

- ``map``: a local east-north-up plane at the field origin. It is a transverse
  Mercator projection centred on the origin, so grid north is true north there and
  the scale is 1: over a field of a few hundred metres it differs from a true ENU
  tangent plane by far less than a millimetre.
- ``field``: ``map`` rotated so +x runs along the rows (``row_bearing_deg``,
  clockwise from north, as a surveyor gives it), origin at the field's origin corner.
- UTM: for georeferenced outputs (LAZ), the zone of the origin.

pyproj is always called with ``always_xy=True`` (lon, lat order).
"""

from __future__ import annotations

import math
from functools import cached_property
from typing import Any

import numpy as np
import numpy.typing as npt
from pyproj import CRS, Transformer

FloatArray = npt.NDArray[np.float64]
WGS84 = CRS.from_epsg(4979)  # 3D: lat, lon, ellipsoidal height


def wrap_angle(a: Any) -> Any:
    """Wrap radians to [-pi, pi)."""
    return (a + math.pi) % (2 * math.pi) - math.pi


def utm_crs(lat: float, lon: float) -> CRS:
    """The WGS84 / UTM CRS of the zone containing (lat, lon), with the grid's two
    exceptions (NGA's UTM/MGRS definition): south-west Norway (56-64 deg N, 3-12 deg E)
    is zone 32, and Svalbard (72-84 deg N) zones 31, 33, 35 and 37 only. pyproj's
    ``query_utm_crs_info`` knows neither (it answers 31N at 60 deg N 4 deg E)."""
    if not (-80.0 <= lat <= 84.0):
        raise ValueError(f"latitude {lat} is outside the UTM range -80..84 deg")
    zone = int((lon + 180.0) // 6.0) % 60 + 1
    if 56.0 <= lat < 64.0 and 3.0 <= lon < 12.0:
        zone = 32
    elif lat >= 72.0 and 0.0 <= lon < 42.0:
        zone = 31 if lon < 9.0 else 33 if lon < 21.0 else 35 if lon < 33.0 else 37
    return CRS.from_epsg((32600 if lat >= 0 else 32700) + zone)


class FieldFrame:
    """Conversions for one georeferenced field.

    ``origin_*``: WGS84 degrees and ellipsoidal metres of the field origin;
    ``row_bearing_deg``: direction of the field +x axis, degrees clockwise from north.
    """

    def __init__(
        self, origin_lat: float, origin_lon: float, origin_alt: float, row_bearing_deg: float
    ) -> None:
        if not (-90.0 <= origin_lat <= 90.0):
            raise ValueError(f"origin_lat {origin_lat} is not a latitude")
        if not (-180.0 <= origin_lon <= 180.0):
            raise ValueError(f"origin_lon {origin_lon} is not a longitude")
        self.origin = (origin_lat, origin_lon, origin_alt)
        self.row_bearing_deg = row_bearing_deg
        # angle of the field x axis from east, counter-clockwise (REP-103 yaw in map)
        self.theta = math.radians(90.0 - row_bearing_deg)
        self.map_crs = CRS.from_proj4(
            f"+proj=tmerc +lat_0={origin_lat} +lon_0={origin_lon} +k=1 +x_0=0 +y_0=0 "
            "+ellps=WGS84 +units=m +no_defs"
        )
        self._to_map = Transformer.from_crs(WGS84, self.map_crs, always_xy=True)
        self._from_map = Transformer.from_crs(self.map_crs, WGS84, always_xy=True)

    @cached_property
    def utm(self) -> CRS:
        return utm_crs(self.origin[0], self.origin[1])

    def wgs84_to_map(self, lat: Any, lon: Any, alt: Any = 0.0) -> tuple[Any, Any, Any]:
        lon, lat, alt = np.broadcast_arrays(lon, lat, np.asarray(alt, dtype=float))
        e, n, u = self._to_map.transform(lon, lat, alt - self.origin[2])
        return e, n, u

    def map_to_wgs84(self, e: Any, n: Any, u: Any = 0.0) -> tuple[Any, Any, Any]:
        e, n, u = np.broadcast_arrays(e, n, np.asarray(u, dtype=float))
        lon, lat, h = self._from_map.transform(e, n, u)
        return lat, lon, np.asarray(h) + self.origin[2]

    def map_to_field(self, e: Any, n: Any) -> tuple[Any, Any]:
        c, s = math.cos(self.theta), math.sin(self.theta)
        e, n = np.asarray(e, dtype=float), np.asarray(n, dtype=float)
        return c * e + s * n, -s * e + c * n

    def field_to_map(self, x: Any, y: Any) -> tuple[Any, Any]:
        c, s = math.cos(self.theta), math.sin(self.theta)
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        return c * x - s * y, s * x + c * y

    def wgs84_to_field(self, lat: Any, lon: Any, alt: Any = 0.0) -> tuple[Any, Any, Any]:
        e, n, u = self.wgs84_to_map(lat, lon, alt)
        x, y = self.map_to_field(e, n)
        return x, y, u

    def field_to_wgs84(self, x: Any, y: Any, z: Any = 0.0) -> tuple[Any, Any, Any]:
        e, n = self.field_to_map(x, y)
        return self.map_to_wgs84(e, n, z)

    def field_to_utm(self, x: Any, y: Any, z: Any = 0.0) -> tuple[Any, Any, Any]:
        lat, lon, h = self.field_to_wgs84(x, y, z)
        t = Transformer.from_crs(WGS84, self.utm, always_xy=True)
        lon, lat, h = np.broadcast_arrays(lon, lat, h)
        east, north, up = t.transform(lon, lat, h)
        return east, north, up

    def enu_cov_to_field(self, cov_enu: npt.ArrayLike) -> FloatArray:
        """A 3x3 ENU (map) covariance expressed in the field frame."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # map -> field
        return rot @ np.asarray(cov_enu, dtype=float).reshape(3, 3) @ rot.T

    def yaw_map_to_field(self, yaw_map: Any) -> Any:
        return wrap_angle(yaw_map - self.theta)

    def yaw_field_to_map(self, yaw_field: Any) -> Any:
        return wrap_angle(yaw_field + self.theta)


def rot_zyx(roll: float, pitch: float, yaw: float) -> FloatArray:
    """Rotation matrix R = Rz(yaw) Ry(pitch) Rx(roll) (body to parent, REP-103)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def euler_zyx(r: npt.ArrayLike) -> tuple[float, float, float]:
    """(roll, pitch, yaw) of a rotation matrix (or of a 4x4 transform's rotation part),
    the inverse of :func:`rot_zyx` (pitch within +-pi/2)."""
    m = np.asarray(r, dtype=np.float64)[:3, :3]
    pitch = -math.asin(min(1.0, max(-1.0, float(m[2, 0]))))
    return (
        math.atan2(float(m[2, 1]), float(m[2, 2])),
        pitch,
        math.atan2(float(m[1, 0]), float(m[0, 0])),
    )


def se3(roll: float, pitch: float, yaw: float, t: npt.ArrayLike) -> FloatArray:
    """4x4 homogeneous transform from ZYX angles and a translation (paper eq. 1)."""
    m = np.eye(4)
    m[:3, :3] = rot_zyx(roll, pitch, yaw)
    m[:3, 3] = np.asarray(t, dtype=float)
    return m


def se2_apply(x: float, y: float, yaw: float, px: Any, py: Any) -> tuple[Any, Any]:
    """Points (px, py) given in a body frame at pose (x, y, yaw) -> parent frame."""
    c, s = math.cos(yaw), math.sin(yaw)
    return x + c * np.asarray(px) - s * np.asarray(py), y + s * np.asarray(px) + c * np.asarray(py)
