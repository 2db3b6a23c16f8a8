import msgspec
import numpy as np
import pytest

from common.field import load_field
from services.sim.robot import RobotState
from services.sim.scene import GROUND, LEAF_HIT, SPHERE
from services.sim.world import World
from services.sim.world_config import BoxObstacle, CylinderObstacle, WorldConfig


@pytest.fixture(scope="module")
def spl():
    return load_field("spl")


@pytest.fixture(scope="module")
def spl_world(spl):
    return World(*spl)


def test_config_decodes_from_toml_with_obstacles():
    toml = b"""
seed = 4
soil = 2.0
[[obstacles]]
type = "box"
x = 1.0
y = 2.0
size_x = 0.5
size_y = 0.5
height = 1.0
[[obstacles]]
type = "cylinder"
x = 3.0
y = 2.0
radius = 0.1
height = 1.7
"""
    cfg = msgspec.toml.decode(toml, type=WorldConfig)
    assert isinstance(cfg.obstacles[0], BoxObstacle)
    assert isinstance(cfg.obstacles[1], CylinderObstacle)
    with pytest.raises(msgspec.ValidationError, match="soil"):
        msgspec.toml.decode(b"soil = -1.0", type=WorldConfig)


def test_world_is_deterministic_and_owns_truth(spl, spl_world):
    a, b = spl_world, World(*spl)
    np.testing.assert_array_equal(a.sphere_centres, b.sphere_centres)
    assert a.sphere_centres.shape == (5, 3)
    z = a.sphere_centres[:, 2] - a.terrain.height(a.sphere_centres[:, 0], a.sphere_centres[:, 1])
    assert np.all((z >= 1.4 + 0.1 - 1e-9) & (z <= 2.0 + 0.1 + 1e-9))
    pts, lab = a.truth_points(0.1)
    assert len(pts) == len(lab)
    for k in (GROUND, LEAF_HIT, SPHERE):
        assert (lab == k).any()


def test_lidar_sees_obstacle_and_plots(spl):
    layout, field = spl
    cfg = WorldConfig(obstacles=[CylinderObstacle(x=3.0, y=0.4, radius=0.1, height=1.0)])
    w = World(layout, field, cfg)
    state = w.settle(RobotState(x=1.0, y=0.4, yaw=0.0))
    r = w.lidar_scan(state, np.random.default_rng(0))
    lx = w.robot.lidar.x
    assert abs(r[540] - (3.0 - 0.1 - 1.0 - lx)) < 0.1
    assert np.isfinite(r).sum() > 100
    # standing, the sweep is cast once and only its noise drawn again: the same as
    # a world that casts it afresh, with the same random numbers
    again = w.lidar_scan(state, np.random.default_rng(1))
    fresh = World(layout, field, cfg).lidar_scan(state, np.random.default_rng(1))
    np.testing.assert_array_equal(again, fresh)
    assert not np.array_equal(again, r)
    moved = w.lidar_scan(w.settle(RobotState(x=1.5, y=0.4, yaw=0.0)), np.random.default_rng(1))
    assert abs(moved[540] - (again[540] - 0.5)) < 0.1


def test_gnss_truth_and_scanner_pose(spl_world):
    w = spl_world
    s = w.settle(RobotState(x=5.0, y=5.0, yaw=0.3))
    ant = w.gnss_truth(s)
    assert np.linalg.norm(ant[0] - ant[1]) == pytest.approx(0.95)
    pose = w.scanner_pose(s)
    assert pose[2, 3] == pytest.approx(s.z + 1.0, abs=0.01)


def test_a_soil_zone_slips_the_robot_where_it_lies_only(spl):
    zone = b"[[soil_zones]]\nx_min = 0.0\ny_min = 0.0\nx_max = 5.0\ny_max = 3.0\nsoil = 3.0\n"
    layout, field = spl
    world = World(layout, field, msgspec.toml.decode(zone, type=WorldConfig))
    assert world.soil_at(2.0, 1.0) == 3.0 and world.soil_at(6.0, 1.0) == 1.0

    def turned(x: float) -> float:
        """Body yaw after 2 s of turning in place at 0.5 rad/s, starting at (x, 1)."""
        s = world.settle(RobotState(x=x, y=1.0, yaw=0.0))
        rng = np.random.default_rng(0)
        for _ in range(100):
            s = world.step_robot(s, 0.0, 0.5, 0.02, rng)
        return s.yaw

    # loose ground scrubs three times the turn away (0.93 of the wheels' rate on
    # firm soil, 0.79 on the zone's)
    assert turned(2.0) < turned(6.0) - 0.1
    with pytest.raises(msgspec.ValidationError, match="soil"):
        msgspec.toml.decode(zone.replace(b"3.0\n", b"-1.0\n"), type=WorldConfig)
