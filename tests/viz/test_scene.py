"""The dashboard's pure core: messages and plans -> rerun archetypes, clouds from files."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import msgspec
import numpy as np
import pytest
import rerun as rr

from common.field import FieldLayout, build_field
from common.field_geojson import field_frame
from common.messages.base import LaserScan
from common.messages.core import Array
from common.messages.gnss import FixType, NavSatFix
from common.messages.mission import MissionPhase, MissionState
from common.messages.nav import PoseEstimate
from common.messages.plan import PlanResult
from common.pointcloud import PosedScan, write_e57, write_laz
from common.robot import LidarMount, ScannerMount, default_robot
from services.planner.core import plan as make_plan
from services.viz import clouds, scene
from services.viz.cli import VizCli
from services.viz.config import VizConfig
from services.viz.outputs import save_path
from tests.conftest import REPO

TINY = REPO / "tests" / "data" / "tiny.toml"
# a lidar at base_link facing forward, a scanner 1 m straight above it
AT_BASE_LINK = LidarMount(x=0.0, y=0.0, z=0.3)
UP_1M = ScannerMount(x=0.0, y=0.0, z=1.0)


@pytest.fixture(scope="module")
def tiny_plan() -> PlanResult:
    layout = msgspec.toml.decode(TINY.read_bytes(), type=FieldLayout)
    return make_plan(layout)


def test_plan_entries_draw_every_plot_candidate_and_leg(tiny_plan: PlanResult) -> None:
    entries = {e.path: e for e in scene.plan_entries(tiny_plan)}
    assert {"field/plots", "field/candidates", "field/selected", "route/legs"} <= set(entries)
    assert all(e.static for e in entries.values())
    plots = entries["field/plots"].item
    assert len(plots.half_sizes.pa_array) == tiny_plan.plot_boxes.shape[0]
    sel = entries["field/selected"].item
    labels = [str(x) for x in sel.labels.pa_array.to_pylist()]
    assert labels == [str(i) for i in tiny_plan.selected]
    assert len(entries["route/legs"].item.strips.pa_array) == len(tiny_plan.legs)


def test_cells_are_counted_by_the_selected_scans_that_see_them(tiny_plan: PlanResult) -> None:
    field = scene.field_of(tiny_plan, [build_field(tiny_plan.layout)])
    assert field is not None
    assert tiny_plan.cell_views is not None
    views = np.asarray(tiny_plan.cell_views.numpy())
    assert views.shape == (field.n_cells,)
    assert views.max() <= len(tiny_plan.selected)
    # the plan covers its target with exactly these locations: same count of seen cells
    assert int((views > 0).sum()) == tiny_plan.cover.cells_covered
    entry = scene.cell_entry(field, views)
    colours = np.asarray(entry.item.colors.pa_array.to_pylist())
    assert len(colours) == field.n_cells
    unseen_colour = int.from_bytes(bytes(scene.VIEW_COLOURS[0]), "big")
    assert int((colours == unseen_colour).sum()) == int((views == 0).sum())


def test_a_plan_of_another_field_has_no_cells(tiny_plan: PlanResult) -> None:
    other = msgspec.structs.replace(tiny_plan.layout, plots_per_row=4)
    assert scene.field_of(tiny_plan, [build_field(other)]) is None


def test_trail_keeps_a_point_per_step_in_overlapping_chunks() -> None:
    trail = scene.Trail(step_m=0.09, chunk=3)
    assert trail.add(0.0, 0.0, 0.0)[0].path == "robot/trail/0000"
    assert trail.add(0.05, 0.0, 0.0) == []  # closer than a step
    paths = [e.path for x in (0.1, 0.2, 0.3) for e in trail.add(x, 0.0, 0.02)]
    assert paths == ["robot/trail/0000", "robot/trail/0000", "robot/trail/0001"]
    last = trail.add(0.4, 0.0, 0.2)[0].item
    pts = np.asarray(last.positions.pa_array.to_pylist())
    # chunk 1 starts at chunk 0's last point (x = 0.2): the drawn line has no gap
    assert pts[:, 0].tolist() == pytest.approx([0.2, 0.3, 0.4])


def test_error_colour_runs_green_to_red() -> None:
    c = scene.error_colour(np.array([0.0, -1.0]), full_scale=0.1)
    assert c[0, 1] > 150 and c[0, 0] < 100
    assert c[1, 0] > 200 and c[1, 1] < 50


def test_lidar_drops_missing_and_out_of_range_returns() -> None:
    r = np.array([1.0, np.inf, 0.01, 2.0, 50.0], dtype=np.float32)
    scan = LaserScan(
        angle_min=0.0,
        angle_max=2.0,
        angle_increment=math.pi / 2,
        range_min=0.1,
        range_max=30.0,
        ranges=Array.of(r),
    )
    pts = np.asarray(scene.lidar_entry(scan, AT_BASE_LINK).item.positions.pa_array.to_pylist())
    assert pts[:, :2] == pytest.approx(np.array([[1.0, 0.0], [0.0, -2.0]]), abs=1e-6)


def test_a_lidar_array_that_lies_about_its_size_raises() -> None:
    bad = Array(dtype="<f4", shape=(10,), data=b"\0" * 8)
    scan = LaserScan(
        angle_min=0, angle_max=1, angle_increment=0.1, range_min=0, range_max=1, ranges=bad
    )
    with pytest.raises(ValueError, match="needs 40 bytes"):
        scene.lidar_entry(scan, AT_BASE_LINK)


def test_a_fix_at_the_field_origin_is_drawn_at_zero(tiny_plan: PlanResult) -> None:
    lay = tiny_plan.layout
    assert lay.origin_lat is not None and lay.origin_lon is not None
    fix = NavSatFix(
        antenna=2,
        latitude=lay.origin_lat,
        longitude=lay.origin_lon,
        altitude=0.0,
        fix_type=FixType.FLOAT,
    )
    e = scene.fix_entry(fix, field_frame(lay))
    assert e.path == "gnss/fix2"
    assert e.item.positions.pa_array.to_pylist()[0] == pytest.approx([0, 0, 0], abs=1e-3)


def test_mission_log_gets_a_line_only_when_the_state_changes() -> None:
    a = MissionState(mission="m", phase=MissionPhase.DRIVING, scans_total=3)
    b = msgspec.structs.replace(a, stamp_ns=5)
    c = msgspec.structs.replace(a, phase=MissionPhase.SCANNING)
    assert [e.path for e in scene.state_entries(None, a)] == ["mission/scans_done", "mission/log"]
    assert [e.path for e in scene.state_entries(a, b)] == ["mission/scans_done"]
    assert "scanning" in str(scene.state_entries(b, c)[1].item.text.pa_array.to_pylist()[0])


def test_a_scan_is_placed_at_its_navigation_pose(tmp_path: Path) -> None:
    f = tmp_path / "scan.e57"
    write_e57(f, [PosedScan.as_scanned([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], np.ones(2), "s")])
    pose = PoseEstimate(x=2.0, y=3.0, yaw=math.pi / 2, z=0.1)
    pts = clouds.scan_in_field(f, pose, pitch=0.0, roll=0.0, mount=UP_1M, n=10)
    assert pts == pytest.approx(np.array([[2.0, 3.0, 1.1], [2.0, 4.0, 1.1]]), abs=1e-5)


def test_an_unreadable_scan_file_is_one_clear_error(tmp_path: Path) -> None:
    (tmp_path / "bad.e57").write_bytes(b"not e57")
    with pytest.raises(clouds.CloudError, match=r"bad\.e57"):
        clouds.scan_in_field(tmp_path / "bad.e57", PoseEstimate(x=0, y=0, yaw=0), 0, 0, UP_1M, 5)


def test_registered_laz_is_read_in_the_field_frame_and_subsampled(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    pts = rng.uniform(0, 5, size=(3000, 3))
    pose = np.eye(4)
    pose[:3, 3] = [10.0, 20.0, 0.0]
    f = tmp_path / "registered.laz"
    write_laz(f, [PosedScan(pts, np.ones(len(pts), np.float32), pose, "s1")], voxel=0.0)
    found = clouds.find_registered(tmp_path, ["registered*.laz"])
    assert found is None  # just written: it may still be growing
    out = clouds.registered(f, 500)
    assert out.shape == (500, 3)
    assert out.min(axis=0) == pytest.approx([10, 20, 0], abs=0.05)
    assert out.max(axis=0) == pytest.approx([15, 25, 5], abs=0.05)


def test_cli_flags_become_config_and_rerun_urls_leave_zenoh_alone() -> None:
    cli = VizCli()
    p = argparse.ArgumentParser()
    p.add_argument("--connect", action="append", default=[])
    cli.add(p)
    zenoh_ep, viewer = "tcp/10.0.0.2:7447", "rerun+http://10.0.0.9:9876/proxy"
    args = p.parse_args(
        ["--serve", "--save", "runs/{mission}/s.rrd", "--connect", zenoh_ep, "--connect", viewer]
    )
    sets = cli.overrides(args)
    assert args.connect == ["tcp/10.0.0.2:7447"]
    from common.config import apply_overrides, decode_section

    cfg = decode_section(apply_overrides({}, sets), VizConfig, "viz")
    assert cfg.serve and cfg.save == "runs/{mission}/s.rrd"
    assert cfg.connect == "rerun+http://10.0.0.9:9876/proxy"


def test_a_second_recording_of_a_mission_does_not_overwrite_the_first(tmp_path: Path) -> None:
    first = save_path("{run_dir}/{mission}/survey.rrd", tmp_path, "m1")
    assert first == tmp_path / "m1" / "survey.rrd"
    first.parent.mkdir()
    first.write_bytes(b"")
    assert save_path("{run_dir}/{mission}/survey.rrd", tmp_path, "m1").name == "survey-2.rrd"


def test_archetypes_log_to_a_recording(tiny_plan: PlanResult, tmp_path: Path) -> None:
    """Everything the scene makes is something rerun accepts (strict mode raises)."""
    rec = rr.RecordingStream("phenorover-test")
    rec.save(tmp_path / "t.rrd")
    entries = [*scene.world(default_robot()), *scene.plan_entries(tiny_plan)]
    entries.append(scene.pose("robot/estimate", 1.0, 2.0, 0.0, 0.5))
    rr.set_strict_mode(True)
    try:
        for e in entries:
            rec.log(e.path, e.item, static=e.static)
    finally:
        rr.set_strict_mode(False)
    rec.disconnect()
    assert (tmp_path / "t.rrd").stat().st_size > 1000
