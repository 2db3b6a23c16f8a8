from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from common.geo import FieldFrame, rot_zyx, utm_crs, wrap_angle

coord = st.floats(-500, 500)


@settings(max_examples=50, deadline=None)
@given(st.floats(-60, 60), st.floats(-179, 179), st.floats(0, 360), coord, coord, st.floats(-5, 5))
def test_field_wgs84_round_trip(
    lat: float, lon: float, bearing: float, x: float, y: float, z: float
) -> None:
    f = FieldFrame(lat, lon, 100.0, bearing)
    bx, by, bz = f.wgs84_to_field(*f.field_to_wgs84(x, y, z))
    assert abs(bx - x) < 1e-6 and abs(by - y) < 1e-6 and abs(bz - z) < 1e-6


def test_row_bearing_east_means_field_is_map() -> None:
    f = FieldFrame(40.0, -88.0, 0.0, 90.0)
    e, n = f.field_to_map(3.0, 4.0)
    assert np.allclose([e, n], [3.0, 4.0])
    f = FieldFrame(40.0, -88.0, 0.0, 0.0)  # rows run north: field x = map y
    e, n = f.field_to_map(3.0, 4.0)
    assert np.allclose([e, n], [-4.0, 3.0])
    assert math.isclose(f.yaw_field_to_map(0.0), math.pi / 2)


def test_field_distances_are_metric() -> None:
    f = FieldFrame(40.0, -88.0, 200.0, 37.0)
    lat, lon, _ = f.field_to_wgs84(np.array([0.0, 100.0]), np.array([0.0, 0.0]))
    e, n, _ = f.wgs84_to_map(lat, lon)
    assert abs(math.hypot(e[1] - e[0], n[1] - n[0]) - 100.0) < 1e-6


def test_utm_zone() -> None:
    assert utm_crs(40.1, -88.2).to_epsg() == 32616
    assert utm_crs(-33.9, 151.2).to_epsg() == 32756
    # the grid's exceptions: Bergen is in 32V, Svalbard's zones are 31X, 33X, 35X, 37X
    assert utm_crs(60.39, 5.32).to_epsg() == 32632
    assert utm_crs(60.39, 2.9).to_epsg() == 32631
    assert utm_crs(78.22, 15.65).to_epsg() == 32633  # Longyearbyen
    svalbard = [utm_crs(80.0, lon).to_epsg() for lon in (8.9, 9.0, 20.9, 21.0, 33.0, 41.9)]
    assert svalbard == [32631, 32633, 32633, 32635, 32637, 32637]
    assert utm_crs(71.9, 10.0).to_epsg() == 32632


@given(st.floats(-100, 100))
def test_wrap_angle_range(a: float) -> None:
    w = wrap_angle(a)
    assert -math.pi <= w < math.pi
    assert math.isclose(math.cos(w), math.cos(a), abs_tol=1e-9)


@given(st.floats(-3, 3), st.floats(-1.5, 1.5), st.floats(-3, 3))
def test_rotation_is_orthonormal(r: float, p: float, y: float) -> None:
    m = rot_zyx(r, p, y)
    assert np.allclose(m @ m.T, np.eye(3)) and math.isclose(np.linalg.det(m), 1.0)
