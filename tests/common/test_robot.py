"""The robot description: it loads, bad values are one clear line, and every service
that uses the robot's geometry follows a change made in the one file."""

from __future__ import annotations

import math
from pathlib import Path

import msgspec
import numpy as np
import pytest

from common.config import ConfigError, decode_section, load_manifest
from common.field import Field, FieldLayout, load_field
from common.field_model import scanner_model
from common.messages.base import LaserScan
from common.messages.core import Array
from common.missionlog import Step
from common.robot import (
    ROBOTS_DIR,
    Robot,
    default_robot,
    dump_robot,
    load_robot,
    robot_path,
)
from common.service import main
from services.base.config import BaseConfig
from services.gnss.compass import BaselineMismatch, Compass, compass_heading
from services.gnss.config import GnssConfig
from services.nav.config import Mounts, NavConfig, check_limits
from services.nav.ekf import EkfConfig, Localizer
from services.nav.follower_config import FollowerConfig
from services.nav.service import build as build_nav
from services.register.runlog import Placement, nav_pose
from services.sim.config import SimConfig
from services.sim.robot import RobotState
from services.sim.terrain import TerrainConfig
from services.sim.world import World
from services.sim.world_config import WorldConfig
from services.viz import scene
from tests.conftest import REPO

TINY = REPO / "tests" / "data" / "tiny.toml"
HUSKY = (ROBOTS_DIR / "husky.toml").read_text()
COV = np.eye(3) * 1e-6


def _write(tmp_path: Path, text: str, name: str = "robot.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def _moved(tmp_path: Path, old: str, new: str) -> Robot:
    """A description that differs from the Husky's in ``old`` -> ``new`` only."""
    assert HUSKY.count(old) == 1, old
    return load_robot(_write(tmp_path, HUSKY.replace(old, new)))


@pytest.fixture(scope="module")
def tiny() -> tuple[FieldLayout, Field]:
    return load_field(TINY)


# --- loading ---


def test_the_shipped_husky_is_the_default_and_deploy_names_the_same_file() -> None:
    r = load_robot("")
    assert r == default_robot() == load_robot("husky") == load_robot(ROBOTS_DIR / "husky.toml")
    # the shipped manifests, the fleet's too: the one file
    for m in (REPO / "deploy").rglob("*.toml"):
        assert robot_path(load_manifest(m).robot) == ROBOTS_DIR / "husky.toml", m
    assert r.name == "husky-a200"
    assert [a.name for a in r.antennas] == ["gnss_1", "gnss_2"]
    # the paper's 0.95 m baseline, 1.10 m up; 990 x 670 x 390 mm; 1.0 m/s
    assert math.dist(r.antennas[0].xyz, r.antennas[1].xyz) == pytest.approx(0.95)
    assert r.antenna_height == pytest.approx(1.10)
    assert (r.footprint.length, r.footprint.width, r.footprint.height) == (0.99, 0.67, 0.39)
    assert r.limits.max_speed == 1.0
    assert robot_path("") == ROBOTS_DIR / "husky.toml"


def test_a_dumped_description_loads_back_unchanged(tmp_path: Path) -> None:
    r = default_robot()
    assert load_robot(_write(tmp_path, dump_robot(r))) == r


def _error(tmp_path: Path, text: str) -> str:
    p = _write(tmp_path, text, "bad.toml")
    with pytest.raises(ConfigError) as e:
        load_robot(p)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"{p}: "), msg
    return msg


@pytest.mark.parametrize(
    ("old", "new", "words"),
    [
        ("x = 0.475\n", "x = 1e9\n", ["<= 10.0", "$.antennas[1].x"]),
        ("x = 0.475\n", "x = nan\n", ["$.antennas[1].x"]),
        ("max_speed = 1.0\n", "max_speed = -1.0\n", ["> 0.0", "$.limits.max_speed"]),
        ("track = 0.555\n", "track = 0.555\nlever = 1.0\n", ["unknown field `lever`"]),
        ('name = "gnss_2"\n', 'name = "gnss_1"\n', ["both are named 'gnss_1'"]),
        ("x = 0.475\n", "x = -0.42\n", ["0.055 m apart", "gnss_1 and gnss_2"]),
        ("track = 0.555\n", "track = 0.9\n", ["outside the footprint"]),
        ("[scanner]\nx = 0.0\n", "[scanner]\nx = 0.0\nz = 2.0\n", ["not valid TOML"]),
    ],
)
def test_a_bad_value_is_one_line_naming_the_file_and_key(
    tmp_path: Path, old: str, new: str, words: list[str]
) -> None:
    assert HUSKY.count(old) == 1, old
    msg = _error(tmp_path, HUSKY.replace(old, new))
    for w in words:
        assert w in msg, msg


def test_one_antenna_is_not_enough(tmp_path: Path) -> None:
    text = HUSKY[: HUSKY.index('[[antennas]]\nname = "gnss_2"')]
    text += HUSKY[HUSKY.index("# The FARO's") :]
    assert "length 2" in _error(tmp_path, text)


def test_a_missing_file_or_example_is_one_line(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nope\.toml: cannot read"):
        load_robot(tmp_path / "nope.toml")
    with pytest.raises(ConfigError, match=r"rover: no such robot description.*husky"):
        load_robot("rover")


# --- the manifest names it ---


def test_the_manifest_names_the_robot_and_the_service_reads_it(tmp_path: Path, capsys) -> None:
    bad = _write(tmp_path, HUSKY.replace("max_speed = 1.0\n", "max_speed = 0.0\n"), "r.toml")
    m = _write(tmp_path, f'machine = "m"\nrobot = "{bad}"\n[services.nav]\n', "m.toml")
    assert load_manifest(m).robot == str(bad)
    # read before the service starts: a bad description stops it with one line
    assert main("nav", NavConfig, build_nav, ["--manifest", str(m), "--dump-config"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "r.toml" in err and "$.limits.max_speed" in err


@pytest.mark.parametrize(
    ("section", "type_", "key"),
    [
        ({"antenna_levers": [[-0.475, 0.0], [0.475, 0.0]]}, NavConfig, "antenna_levers"),
        ({"antenna_height_m": 1.1}, NavConfig, "antenna_height_m"),
        ({"lidar_xy": [0.45, 0.0]}, NavConfig, "lidar_xy"),
        ({"backend": "sim", "max_speed": 1.0}, BaseConfig, "max_speed"),
        ({"backend": "sim", "compass": {"antenna2_xyz_m": [0.5, 0, 1]}}, GnssConfig, "antenna2"),
        ({"world": {"scanner_mount": [0, 0, 1]}}, SimConfig, "scanner_mount"),
        ({"world": {"robot": {"wheelbase": 0.5}}}, SimConfig, "wheelbase"),
        ({"world": {"lidar": {"mount_xyz": [0.4, 0, 0.3]}}}, SimConfig, "mount_xyz"),
    ],
)
def test_a_manifest_still_setting_a_moved_key_is_told_where_it_went(
    section: dict[str, object], type_: type[msgspec.Struct], key: str
) -> None:
    with pytest.raises(ConfigError) as e:
        decode_section(section, type_, "m.toml: [services.x]")
    msg = str(e.value)
    assert "\n" not in msg and key in msg and "moved to the robot description" in msg, msg


def test_nav_refuses_a_follower_faster_than_the_robot(tmp_path: Path) -> None:
    slow = _moved(tmp_path, "max_speed = 1.0\n", "max_speed = 0.1\n")
    check_limits(NavConfig(), default_robot())
    with pytest.raises(ConfigError, match=r"follower\] max_speed = 0.5 .* max_speed = 0.1"):
        check_limits(NavConfig(), slow)
    check_limits(NavConfig(follower=FollowerConfig(max_speed=0.1)), slow)


# --- one change, every consumer follows ---


def _flat_world(tiny: tuple[FieldLayout, Field], robot: Robot) -> World:
    flat = WorldConfig(terrain=TerrainConfig(slope_pct=0.0, bump_rms=0.0))
    return World(tiny[0], tiny[1], flat, robot)


def _localize(truth: np.ndarray, compass: Compass, mounts: Mounts) -> np.ndarray:
    """What nav estimates (x, y, yaw) from a standing robot's two antenna truths."""
    loc = Localizer(EkfConfig())
    yaw = compass_heading(truth[0], truth[1], COV, COV, compass).yaw_rad
    for k in range(30):
        t = 0.1 * k
        loc.update_odometry(t, 0.0, 0.0, 1e-6, 1e-6, still=True)
        loc.update_heading(t, yaw, 0.005)
        for lever, p in zip(mounts.levers, truth, strict=True):
            loc.update_antenna(t, p[:2], np.eye(2) * 1e-4, lever[:2])
    return loc.x[:3].copy()


def test_moving_one_antenna_moves_sim_truth_gnss_and_nav(
    tiny: tuple[FieldLayout, Field], tmp_path: Path
) -> None:
    husky = default_robot()
    moved = _moved(tmp_path, "x = 0.475\ny = 0.0\nz = 1.10\n", "x = 0.60\ny = 0.0\nz = 1.20\n")
    state = RobotState(x=5.0, y=3.0, yaw=0.4)
    before = _flat_world(tiny, husky)
    after = _flat_world(tiny, moved)
    s = after.settle(state)

    # sim: the antenna's true position follows; the other stays
    truth = after.gnss_truth(s)
    c, sn = math.cos(0.4), math.sin(0.4)
    assert truth[1] == pytest.approx([5.0 + 0.60 * c, 3.0 + 0.60 * sn, s.z + 1.20])
    assert truth[0] == pytest.approx(before.gnss_truth(before.settle(state))[0])

    # gnss: the compass expects the new baseline (the old one would refuse it)
    compass = Compass.of(moved)
    h = compass_heading(truth[0], truth[1], COV, COV, compass)
    assert h.yaw_rad == pytest.approx(0.4, abs=1e-9)
    assert h.baseline_m == pytest.approx(math.dist(*(a.xyz for a in moved.antennas)))
    with pytest.raises(BaselineMismatch):
        compass_heading(truth[0], truth[1], COV, COV, Compass.of(husky))

    # nav: the EKF's lever arms (heights included) follow, so it finds base_link
    mounts = Mounts.of(moved)
    assert mounts.levers == ((-0.475, 0.0, 1.10), (0.60, 0.0, 1.20))
    est = _localize(truth, compass, mounts)
    assert est[:2] == pytest.approx([5.0, 3.0], abs=1e-3)
    assert est[2] == pytest.approx(0.4, abs=1e-3)
    stale = _localize(truth, compass, Mounts.of(husky))
    assert math.hypot(stale[0] - 5.0, stale[1] - 3.0) > 0.05  # the stale lever is seen

    # register: the antennas' height it undoes the planar EKF's lean with
    assert Placement.of(moved).antenna_height == pytest.approx(1.15)


def test_moving_the_scanner_moves_sim_register_viz_and_the_plan(
    tiny: tuple[FieldLayout, Field], tmp_path: Path
) -> None:
    moved = _moved(
        tmp_path,
        "x = 0.0\ny = 0.0\nz = 1.0\nyaw_deg = 0.0\n",
        "x = 0.2\ny = -0.1\nz = 1.3\nyaw_deg = 90.0\n",
    )
    world = World(tiny[0], tiny[1], None, moved)
    s = world.settle(RobotState(x=5.0, y=3.0, yaw=0.4))
    assert abs(s.pitch) + abs(s.roll) > 1e-3  # on the tilted default terrain
    truth = world.scanner_pose(s)
    # the scanner's own axes: its x (zero azimuth) is base_link's y
    base = np.array([[-math.sin(0.4)], [math.cos(0.4)]])
    assert truth[:2, 0:1] == pytest.approx(base, abs=0.03)

    # register: the navigation pose of a scan places the scanner where the sim has it
    place = Placement.of(moved)
    assert place.lever == (0.2, -0.1, 1.3) and place.mount_yaw_deg == 90.0
    lean = truth[:3, :3] @ np.array([0.0, 0.0, place.antenna_height])  # the planar EKF's
    # the compensator measures the scanner's tilt (ZYX of its own axes)
    pitch = -math.asin(truth[2, 0])
    roll = math.atan2(truth[2, 1], truth[2, 2])
    step = Step(
        idx=1,
        scan_id=1,
        cand_id=1,
        x=s.x,
        y=s.y,
        yaw=s.yaw,
        status="done",
        attempts=1,
        mean_x=s.x + lean[0],
        mean_y=s.y + lean[1],
        mean_z=s.z,
        mean_yaw=s.yaw,
        pitch=pitch,
        roll=roll,
    )
    m = nav_pose(step, place)
    assert m[:3, 3] == pytest.approx(truth[:3, 3], abs=1e-3)
    assert m[:3, :3] == pytest.approx(truth[:3, :3], abs=1e-3)

    # the plan: the planner casts rays from the new height
    assert scanner_model(moved).height == 1.3

    # viz: the dashboard's body and lidar points come from the description too
    wide = _moved(tmp_path, "width = 0.67\n", "width = 0.80\n")
    body = next(e for e in scene.world(wide) if e.path == "robot/estimate/body")
    half = body.item.half_sizes.pa_array.to_pylist()[0]
    assert half == pytest.approx([0.495, 0.40, 0.195])
    turned = _moved(
        tmp_path,
        "x = 0.45\ny = 0.0\nz = 0.35\nyaw_deg = 0.0\n",
        "x = 0.3\ny = 0.1\nz = 0.5\nyaw_deg = 90.0\n",
    )
    scan = LaserScan(
        angle_min=0.0,
        angle_max=0.0,
        angle_increment=0.1,
        range_min=0.1,
        range_max=5.0,
        ranges=Array.of(np.array([2.0], dtype=np.float32)),
    )
    pts = scene.lidar_entry(scan, turned.lidar).item.positions.pa_array.to_pylist()
    assert pts[0] == pytest.approx([0.3, 2.1, 0.5])
