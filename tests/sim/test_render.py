from pathlib import Path

import numpy as np
import pytest

from common.field import load_field
from common.geo import se3
from common.pointcloud import PosedScan, read_e57, write_e57
from services.sim.foliage import build_foliage
from services.sim.plant_config import FoliageConfig
from services.sim.render import (
    FaroNoise,
    ScanSettings,
    range_sigma,
    render,
    scan_grid,
)
from services.sim.robot import RobotState
from services.sim.scene import GROUND, LEAF_HIT, POLE, SPHERE, STEM_HIT, Scene
from services.sim.terrain import TerrainConfig, build_terrain
from services.sim.world import World


def _read(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points, intensity and pose of a single-scan E57 file."""
    (scan,) = read_e57(path)
    return scan.points, scan.intensity, scan.pose


EMPTY5, EMPTY6, EMPTY7 = np.zeros((0, 5)), np.zeros((0, 6)), np.zeros((0, 7))
# a window around +x, coarse enough to stay fast
WINDOW = ScanSettings(
    vertical_start_deg=-5,
    vertical_end_deg=5,
    horizontal_start_deg=-5,
    horizontal_end_deg=5,
    step_deg=0.1,
)


def test_grid_matches_the_paper():
    el, az = scan_grid(ScanSettings())
    assert (len(el), len(az)) == (417, 1000)


def test_noise_model_reproduces_datasheet():
    n = FaroNoise()
    s = range_sigma(np.array([10.0, 25.0, 10.0, 25.0]), np.array([0.9, 0.9, 0.1, 0.1]), n)
    np.testing.assert_allclose(s * 1e3, [0.3, 0.3, 0.4, 0.5], atol=0.015)


def test_single_sphere_is_recovered():
    c = np.array([10.0, 0.0, 1.0])
    scene = Scene(None, None, np.array([[*c, 0.1, SPHERE]]), EMPTY6, EMPTY7)
    pose = se3(0.0, 0.0, 0.0, [0.0, 0.0, 1.0])
    s = render(scene, pose, WINDOW, np.random.default_rng(0))
    assert np.all(s.label == SPHERE) and len(s.points) > 20
    centre_scanner = c - pose[:3, 3]
    dist = np.linalg.norm(s.points - centre_scanner, axis=1)
    # noise: 1 mm bias + 0.3 mm ranging + 19" angles (~1 mm at 10 m) on a curved surface
    assert np.abs(dist - 0.1).max() < 0.006
    assert abs(np.median(dist) - 0.1) < 0.0015
    # the front of the sphere is at ~9.9 m
    assert abs(np.linalg.norm(s.points, axis=1).min() - 9.9) < 0.005


def test_pose_rotates_into_the_scanner_frame():
    c = np.array([3.0, 10.0, 1.0])
    scene = Scene(None, None, np.array([[*c, 0.1, SPHERE]]), EMPTY6, EMPTY7)
    pose = se3(0.0, 0.0, np.pi / 2, [3.0, 0.0, 1.0])  # facing +y: the sphere is ahead
    s = render(scene, pose, WINDOW, np.random.default_rng(1))
    assert len(s.points) > 20
    assert np.median(s.points[:, 0]) == pytest.approx(9.9, abs=0.05)


def test_plot_occludes_the_sphere():
    ter = build_terrain(np.array([0.0, -2.0, 12.0, 2.0]), TerrainConfig(bump_rms=0.0), 0)
    # a 3 x 1 m plot seen end-on, as along a row: 3 m of canopy in the way
    plot = np.array([[4.0, -0.5, 0.0, 7.0, 0.5, 1.9]])
    fol = build_foliage(plot, ter, FoliageConfig(), 0)
    sphere = np.array([[10.0, 0.0, float(ter.height(10, 0)) + 1.0, 0.1, SPHERE]])
    pose = se3(0.0, 0.0, 0.0, [0.0, 0.0, float(ter.height(0, 0)) + 1.0])
    rng = np.random.default_rng(2)
    open_scan = render(Scene(ter, None, sphere, EMPTY6, EMPTY7), pose, WINDOW, rng)
    hidden = render(Scene(ter, fol, sphere, EMPTY6, EMPTY7), pose, WINDOW, rng)
    n_open = int((open_scan.label == SPHERE).sum())
    assert n_open > 50
    assert (hidden.label == SPHERE).sum() < 0.05 * n_open
    assert ((hidden.label == LEAF_HIT) | (hidden.label == STEM_HIT)).sum() > 100


@pytest.fixture(scope="module")
def engr():
    layout, field = load_field("engr")
    return World(layout, field)


def test_engr_scan_sees_ground_plants_and_spheres(engr, tmp_path):
    # a planned scan location (ENGR candidate 64): the spheres are placed for those
    state = engr.settle(RobotState(x=1.5, y=17.2, yaw=0.0))
    pose = engr.scanner_pose(state)
    s = engr.render_scan(pose, ScanSettings(), np.random.default_rng(3))
    counts = np.bincount(s.label, minlength=8)
    assert counts[GROUND] > 1000 and counts[LEAF_HIT] > 1000 and counts[STEM_HIT] > 100
    assert counts[SPHERE] > 0 and counts[POLE] > 0
    r = np.linalg.norm(s.points, axis=1)
    assert r.min() >= 0.6 - 0.01 and r.max() <= 70.0
    assert s.shape == (417, 1000) and s.row.max() < 417 and s.col.max() < 1000
    # sphere points land on the true spheres once placed with the true pose
    world = s.points[s.label == SPHERE] @ pose[:3, :3].T + pose[:3, 3]
    d = np.linalg.norm(world[:, None, :] - engr.sphere_centres[None], axis=2).min(axis=1)
    assert np.abs(d - 0.1).max() < 0.01

    path = tmp_path / "scan.e57"
    write_e57(path, [PosedScan(s.points, s.intensity.astype(np.float32), pose, "loc74")])
    pts, inten, pose_back = _read(path)
    np.testing.assert_allclose(pts, s.points, atol=1e-5)
    np.testing.assert_allclose(inten, s.intensity, atol=1e-6)
    np.testing.assert_allclose(pose_back, pose, atol=1e-9)


def test_e57_without_pose_reads_identity(tmp_path):
    pts = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    write_e57(tmp_path / "a.e57", [PosedScan.as_scanned(pts, [0.1, 0.2], "a")])
    back, _, pose = _read(tmp_path / "a.e57")
    np.testing.assert_allclose(back, pts, atol=1e-6)
    np.testing.assert_allclose(pose, np.eye(4))
    with pytest.raises(ValueError, match="do not match"):
        write_e57(tmp_path / "b.e57", [PosedScan.as_scanned(pts, [0.1], "b")])
