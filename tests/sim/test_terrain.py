import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from services.sim.terrain import TerrainConfig, build_terrain, ray_terrain

BOUNDS = np.array([0.0, 0.0, 30.0, 20.0])
TERRAIN = build_terrain(BOUNDS, TerrainConfig(margin=5.0), seed=3)


@settings(max_examples=200, deadline=None)
@given(st.floats(-5, 35), st.floats(-5, 25), st.floats(-0.01, 0.01), st.floats(-0.01, 0.01))
def test_height_is_continuous(x, y, dx, dy):
    h0 = TERRAIN.height(x, y)
    h1 = TERRAIN.height(x + dx, y + dy)
    # 1 % slope plus 3 cm bumps over 1.5 m: gradients stay well under 0.5
    assert abs(h1 - h0) <= 0.5 * math.hypot(dx, dy) + 1e-12


def test_plane_slope_and_normal():
    cfg = TerrainConfig(slope_pct=2.0, slope_dir_deg=0.0, bump_rms=0.0, margin=2.0)
    ter = build_terrain(BOUNDS, cfg, seed=0)
    x = np.linspace(1, 29, 15)
    h = ter.height(x, 7.3)
    np.testing.assert_allclose(np.diff(h) / np.diff(x), 0.02, atol=1e-9)
    assert abs(float(ter.height(15.0, 10.0))) < 1e-9  # zero at the field centre
    n = ter.normal(12.3, 4.5)
    np.testing.assert_allclose(n, np.array([-0.02, 0.0, 1.0]) / math.hypot(0.02, 1), atol=1e-9)


def test_bumps_have_configured_size_and_are_seeded():
    cfg = TerrainConfig(slope_pct=0.0, bump_rms=0.03, margin=0.0)
    a = build_terrain(BOUNDS, cfg, seed=1)
    b = build_terrain(BOUNDS, cfg, seed=1)
    c = build_terrain(BOUNDS, cfg, seed=2)
    assert 0.025 < a.grid.std() < 0.035
    np.testing.assert_array_equal(a.grid, b.grid)
    assert not np.array_equal(a.grid, c.grid)


def test_outside_grid_is_clamped_and_finite():
    h = TERRAIN.height([-1000.0, 1000.0], [0.0, 1000.0])
    assert np.all(np.isfinite(h))


def test_ray_hits_the_surface():
    t = TERRAIN
    o = np.array([12.0, 8.0, 3.0])
    for d in (np.array([0.0, 0.0, -1.0]), np.array([0.6, 0.0, -0.8])):
        hit = ray_terrain(t.grid, t.x0, t.y0, t.spacing, t.hmin, t.hmax, o, d, 100.0)
        p = o + hit * d
        assert abs(p[2] - t.height(p[0], p[1])) < 1e-6
    up = ray_terrain(t.grid, t.x0, t.y0, t.spacing, t.hmin, t.hmax, o, np.array([0, 0, 1.0]), 50)
    assert up == np.inf
