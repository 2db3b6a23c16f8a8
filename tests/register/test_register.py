import math

import laspy
import msgspec
import numpy as np
import pytest
from scipy.spatial import cKDTree

from common.field import load_field
from common.geo import euler_zyx, rot_zyx
from common.pointcloud import CloudIOError, PosedScan, read_e57, write_e57, write_laz
from common.poses import (
    PoseError,
    apply,
    inv,
    scanner_pose,
    tilt_from_axis_inclinations,
)
from services.register.graph import TargetObservation, optimise_graph
from services.register.metrics import cloud_distance, overlap_stats, point_stats
from services.register.poses import perturb
from services.register.refine import (
    RefineConfig,
    align_pair,
    pair_information,
    prepare,
    prior_sigmas,
    refine,
)
from services.register.spheres import SphereConfig, detect_spheres, fit_sphere
from services.register.targets import solve_targets
from services.sim.render import ScanSettings
from services.sim.robot import RobotState
from services.sim.world import World


def _partial_sphere(rng, centre, radius, n=400, noise=0.001, cap=0.3):
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    view = -centre / np.linalg.norm(centre)  # the cap facing the scanner at the origin
    d = d[d @ view > cap]
    return centre + radius * d + rng.normal(scale=noise, size=d.shape)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sphere_fit_recovers_centre_and_radius_from_a_noisy_cap(seed):
    rng = np.random.default_rng(seed)
    centre = rng.uniform([3, -5, 0], [10, 5, 2])
    pts = _partial_sphere(rng, centre, 0.1)
    known = fit_sphere(pts, 0.1)
    free = fit_sphere(pts, None)
    assert np.linalg.norm(known.centre - centre) < 0.002
    assert np.linalg.norm(free.centre - centre) < 0.002
    assert abs(free.radius - 0.1) < 0.002
    assert known.rms < 0.002


def test_detect_spheres_among_clutter():
    rng = np.random.default_rng(3)
    centre = np.array([6.0, 1.0, 0.8])
    sph = _partial_sphere(rng, centre, 0.1, n=800)
    ground = np.column_stack(
        [rng.uniform(1, 10, 5000), rng.uniform(-4, 4, 5000), np.full(5000, -1)]
    )
    pts = np.vstack([sph, ground])
    inten = np.concatenate([rng.uniform(0.6, 0.85, len(sph)), rng.uniform(0.1, 0.4, len(ground))])
    found = detect_spheres(pts, inten, SphereConfig())
    assert len(found) == 1
    assert np.linalg.norm(found[0].fit.centre - centre) < 0.002


def test_navigation_pose_matches_the_sim_scanner_pose():
    layout, field = load_field("spl")
    world = World(layout, field)
    s = world.settle(RobotState(x=5.0, y=3.0, yaw=0.4))
    nav = scanner_pose(s.x, s.y, s.z, s.yaw, s.pitch, s.roll, lever=world.robot.scanner.xyz)
    np.testing.assert_allclose(nav, world.scanner_pose(s), atol=1e-12)
    roll, pitch, yaw = euler_zyx(nav)
    assert (roll, pitch, yaw) == pytest.approx((s.roll, s.pitch, s.yaw))
    with pytest.raises(PoseError, match="non-finite"):
        scanner_pose(math.nan, 0, 0, 0, 0, 0)


def test_axis_inclinations_give_zyx_tilt():
    r = rot_zyx(0.02, -0.03, 1.0)
    ix, iy = math.asin(r[2, 0]), math.asin(r[2, 1])
    assert tilt_from_axis_inclinations(ix, iy) == pytest.approx((-0.03, 0.02), abs=1e-12)


def test_the_target_solution_recovers_poses():
    rng = np.random.default_rng(4)
    targets = rng.uniform([-5, -5, 1], [5, 5, 2], (4, 3))
    truth = [perturb(np.eye(4), rng.normal(0, 1, 3), rng.normal(0, 0.1, 3)) for _ in range(3)]
    seen = [apply(inv(t), targets) for t in truth]
    nav = [perturb(t, rng.normal(0, 0.03, 3), np.radians([0.0, 0.0, 0.5])) for t in truth]
    sol = solve_targets(seen, nav)
    assert sol.solved == [True, True, True]
    # the targets fix the relative poses; the gauge follows the navigation poses
    for t, p in zip(truth, sol.poses, strict=True):
        rel = inv(sol.poses[0]) @ p - inv(truth[0]) @ t
        assert np.abs(rel).max() < 1e-4


def test_shared_spheres_tie_scans_in_the_pose_graph_without_any_pair():
    # two scans with no cloud pair, both seeing the same two spheres (and the
    # compensator's tilt): the graph recovers their relative pose, which the
    # navigation alone gets wrong by centimetres and 0.5 deg
    rng = np.random.default_rng(5)
    spheres = np.array([[3.0, 1.0, 1.8], [-2.0, 4.0, 1.6]])
    truth = [
        perturb(np.eye(4), [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]),
        perturb(np.eye(4), [4.0, 3.0, 1.1], [0.0, 0.0, 1.0]),
    ]
    nav = [
        perturb(t, rng.normal(0, 0.02, 3), np.radians([0.0, 0.0, d]))
        for t, d in zip(truth, (0.5, -0.5), strict=True)
    ]
    obs = [
        TargetObservation(i, k, apply(inv(t), spheres[k : k + 1])[0])
        for i, t in enumerate(truth)
        for k in range(2)
    ]
    cfg = RefineConfig(nav_sigma_xy=0.02)  # what these navigation poses are worth
    alone = optimise_graph(nav, [], prior_sigmas(cfg))
    tied = optimise_graph(nav, [], prior_sigmas(cfg), obs, 0.001)

    def rel_error(poses):
        return np.abs(inv(poses[0]) @ poses[1] - inv(truth[0]) @ truth[1]).max()

    assert rel_error(alone) > 0.01
    assert rel_error(tied) < 1e-3


@pytest.fixture(scope="module")
def lane_scans():
    layout, field = load_field("engr")
    world = World(layout, field)
    rng = np.random.default_rng(7)
    out = []
    for y in (11.8, 15.4):
        state = world.settle(RobotState(x=1.5, y=y, yaw=0.0))
        true = world.scanner_pose(state)
        out.append((world.render_scan(true, ScanSettings(step_deg=0.5), rng), true))
    return out


def test_refinement_restores_a_perturbed_pair(lane_scans):
    (s0, t0), (s1, t1) = lane_scans
    nav = [
        perturb(t0, [0.02, -0.01, 0.03], np.radians([0.1, -0.1, 0.5])),
        perturb(t1, [-0.03, 0.02, -0.02], np.radians([-0.1, 0.1, -0.8])),
    ]
    cfg = RefineConfig(nav_sigma_xy=0.02)  # navigation poses 2-3 cm off
    poses, pairs = refine([prepare(s.points, cfg) for s in (s0, s1)], nav, cfg)
    assert pairs[0].kept, pairs[0].reason
    sample = s1.points[::20]
    sample = sample[np.linalg.norm(sample, axis=1) < 20]
    before = point_stats([sample], [inv(nav[0]) @ nav[1]], [inv(t0) @ t1])
    after = point_stats([sample], [inv(poses[0]) @ poses[1]], [inv(t0) @ t1])
    assert before.mean > 0.05
    assert after.mean < 0.01


def test_refinement_is_the_same_on_one_or_two_workers(lane_scans):
    """Each pair is one single-threaded job: where it runs changes nothing, to the bit."""
    (s0, t0), (s1, t1) = lane_scans
    nav = [
        perturb(t0, [0.01, -0.01, 0.02], np.radians([0.05, -0.05, 0.3])),
        perturb(t1, [-0.02, 0.01, -0.01], np.radians([-0.05, 0.05, -0.4])),
        perturb(t0, [0.0, 0.02, 0.0], np.radians([0.0, 0.0, 0.2])),  # s0 seen again
    ]
    prepared = [prepare(s.points, RefineConfig()) for s in (s0, s1, s0)]
    one = refine(prepared, nav, RefineConfig(threads=1))
    two = refine(prepared, nav, RefineConfig(threads=2))
    assert [(p.i, p.j) for p in two[1]] == [(0, 1), (0, 2), (1, 2)]
    for a, b in zip(one[1], two[1], strict=True):
        assert (a.overlap, a.rmse, a.kept, a.reason) == (b.overlap, b.rmse, b.kept, b.reason)
        assert np.array_equal(a.t_ij, b.t_ij) and np.array_equal(a.info, b.info)
    assert all(np.array_equal(a, b) for a, b in zip(one[0], two[0], strict=True))


def test_a_pair_overlapping_too_little_at_the_start_is_refused_before_gicp(lane_scans):
    """Fewer than ``min_overlap`` of the points within the coarse radius at the start
    cannot end with that share within the fine one: the pair is refused unaligned."""
    (s0, t0), (s1, t1) = lane_scans
    cfg = RefineConfig()
    a, b = prepare(s0.points, cfg), prepare(s1.points, cfg)
    t_ij = inv(t0) @ t1
    aligned = align_pair(0, 1, a, b, t_ij, cfg)
    assert math.isfinite(aligned.rmse)
    # the same pair, asked for more overlap than lies within 0.3 m of it at the start
    strict = msgspec.structs.replace(cfg, min_overlap=0.99)
    refused = align_pair(0, 1, a, b, t_ij, strict)
    assert not refused.kept and math.isinf(refused.rmse) and "at the start" in refused.reason
    assert np.array_equal(refused.t_ij, t_ij)


def test_pair_information_counts_a_denser_scan_of_the_same_surface_once():
    """Sampling the same surfaces ten times more densely adds no independent evidence:
    with independent_voxel the information stays put, without it it grows tenfold."""
    rng = np.random.default_rng(2)

    def corner(n):  # three orthogonal 4 m walls, so all six directions are constrained
        u = rng.uniform(0, 4, (n, 2))
        pts = np.vstack(
            [np.c_[u, np.zeros(n)], np.c_[u[:, 0], np.zeros(n), u[:, 1]], np.c_[np.zeros(n), u]]
        )
        nrm = np.repeat(np.eye(3)[::-1], n, axis=0)
        return pts, nrm

    tgt, nrm = corner(20000)
    kd = cKDTree(tgt)
    sparse, dense = corner(2000)[0], corner(20000)[0]
    for voxel, ratio in ((0.5, 1.0), (0.0, 10.0)):
        i_sparse = pair_information(kd, nrm, sparse, 0.1, 0.01, voxel)
        i_dense = pair_information(kd, nrm, dense, 0.1, 0.01, voxel)
        assert np.trace(i_dense) / np.trace(i_sparse) == pytest.approx(ratio, rel=0.05)
    # about 64 cubes per wall (fewer where walls share cubes at their edges): with the
    # rotation held, a shift along a wall's normal is known to about sigma / 8, not
    # sigma / sqrt(20000)
    info = pair_information(kd, nrm, dense, 0.1, 0.01, 0.5)
    assert info[3, 3] ** -0.5 == pytest.approx(0.01 / 8, rel=0.1)


def test_cloud_distance_of_a_shift():
    rng = np.random.default_rng(5)
    ref = rng.uniform(0, 10, (20000, 3))
    d = cloud_distance(ref + np.array([0.0, 0.0, 0.01]), ref)
    assert d.mean == pytest.approx(0.01, abs=1e-3)
    assert d.below_2cm == 1.0
    assert d.axis_mean[2] == pytest.approx(0.01, abs=1e-3)


def test_overlap_residuals_need_no_reference_and_grow_with_a_pose_error():
    rng = np.random.default_rng(3)
    g = np.arange(-3.0, 3.0, 0.02)
    xx, yy = np.meshgrid(g, g)
    ground = np.column_stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)])
    where = [(0.0, 0.0), (1.0, 0.0), (40.0, 0.0)]  # the third sees ground of its own
    poses = [perturb(np.eye(4), np.array([x, y, 1.2]), np.zeros(3)) for x, y in where]
    world = [ground + np.array([x, 0.0, 0.0]) if x > 10 else ground for x, _ in where]
    full = [apply(inv(p), w) for p, w in zip(poses, world, strict=True)]
    samples = []
    for p, (x, _) in zip(poses, where, strict=True):
        s = np.column_stack([rng.uniform(-3, 3, (2000, 2)), np.zeros(2000)])
        samples.append(apply(inv(p), s + np.array([x if x > 10 else 0.0, 0.0, 0.0])))
    up = np.tile([0.0, 0.0, 1.0], (len(ground), 1))  # the poses do not rotate
    clouds = [(f, up, cKDTree(f)) for f in full]
    pairs = [(0, 1), (0, 2), (1, 2)]

    right = overlap_stats(clouds, samples, poses, pairs, 0.3)
    assert [(p.i, p.j) for p in right.pairs] == [(0, 1)]  # the far scan overlaps none
    assert right.mean < 1e-6 and right.max == right.pairs[0].mean
    # scan 1 placed 3 cm too high: its points stand 3 cm off scan 0's ground, measured
    # along the ground's normal whatever the sampling
    wrong = [poses[0], perturb(poses[1], np.array([0.0, 0.0, 0.03]), np.zeros(3)), poses[2]]
    off = overlap_stats(clouds, samples, wrong, pairs, 0.3)
    assert off.mean == pytest.approx(0.03, abs=1e-6)
    # nothing within the radius: no pair, no figure
    assert overlap_stats(clouds, samples, wrong, pairs, 0.02).count == 0


def _scans(rng):
    return [
        PosedScan(
            rng.uniform(-5, 5, (500, 3)),
            rng.uniform(0, 1, 500).astype(np.float32),
            perturb(np.eye(4), rng.uniform(-10, 10, 3), rng.normal(0, 0.5, 3)),
            f"scan_{k}",
        )
        for k in range(3)
    ]


def test_multi_scan_e57_round_trip(tmp_path):
    scans = _scans(np.random.default_rng(6))
    path = tmp_path / "registered.e57"
    write_e57(path, scans)
    back = read_e57(path)
    assert [b.name for b in back] == [s.name for s in scans]
    for a, b in zip(scans, back, strict=True):
        np.testing.assert_allclose(b.pose, a.pose, atol=1e-9)
        np.testing.assert_allclose(b.points, a.points, atol=1e-5)
        np.testing.assert_allclose(b.intensity, a.intensity, atol=1e-6)
    with pytest.raises(CloudIOError, match="no scans"):
        write_e57(path, [])


def test_laz_written_in_field_and_utm(tmp_path):
    scans = _scans(np.random.default_rng(8))
    n = write_laz(tmp_path / "merged.laz", scans, voxel=0.0)
    las = laspy.read(tmp_path / "merged.laz")
    assert len(las.points) == n == 1500
    want = np.vstack([apply(s.pose, s.points) for s in scans])
    got = np.column_stack([las.x, las.y, las.z])
    assert np.abs(got - want).max() <= 0.0006
    np.testing.assert_array_equal(np.unique(las.point_source_id), [0, 1, 2])

    def utm(x, y, z):
        return x + 500000.0, y + 3700000.0, z + 200.0

    write_laz(tmp_path / "utm.laz", scans, voxel=0.5, to_utm=utm, epsg=32617)
    las = laspy.read(tmp_path / "utm.laz")
    assert las.x.min() > 499000 and las.y.min() > 3699000
    assert las.header.parse_crs().to_epsg() == 32617
