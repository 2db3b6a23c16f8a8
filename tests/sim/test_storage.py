"""Where the simulator may write (scan paths from the render RPC), and atomic writes:
a reader sees the old file or the whole new one, never a part; and the world snapshot
that lets a restarted simulator continue."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from common.field import load_field
from common.files import atomic_path, write_atomic
from common.pointcloud import PosedScan, read_e57, write_e57
from phenorover.eval.register.truth import read_truth
from services.sim import snapshot
from services.sim.robot import RobotState
from services.sim.storage import PathRefused, confine
from services.sim.truth_file import ScanTruth, write_truth
from services.sim.world_config import WorldConfig


def _read(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points, intensity and pose of a single-scan E57 file."""
    (scan,) = read_e57(path)
    return scan.points, scan.intensity, scan.pose


FIELD = "RenderRequest.path"


def test_paths_under_the_scan_folder_are_accepted(tmp_path: Path) -> None:
    card = tmp_path / "card"
    p = confine(str(card / "proj-1" / "Scan_00001.e57"), card, ".e57", FIELD)
    assert p == (card / "proj-1" / "Scan_00001.e57").resolve()
    assert confine("Scan_00002.e57", card, ".e57", FIELD) == (card / "Scan_00002.e57").resolve()


@pytest.mark.parametrize(
    ("path", "why"),
    [
        ("/etc/cron.d/x.e57", "outside the scan folder"),
        ("{card}/../x.e57", "outside the scan folder"),
        ("{card}/a/../../x.e57", "outside the scan folder"),
        ("{card}/link/x.e57", "outside the scan folder"),
        ("{card}/Scan_1.txt", "is not a .e57 file"),
        ("{card}/we ird/x.e57", "'we ird' is not an allowed file name"),
        ("{card}/.hidden.e57", "'.hidden.e57' is not an allowed file name"),
    ],
)
def test_other_paths_are_refused_naming_the_field(tmp_path: Path, path: str, why: str) -> None:
    card = tmp_path / "card"
    card.mkdir()
    (card / "link").symlink_to(tmp_path)
    with pytest.raises(PathRefused, match=f"^RenderRequest.path: .*{why}"):
        confine(path.format(card=card), card, ".e57", FIELD)


def test_atomic_write_replaces_whole_or_not_at_all(tmp_path: Path) -> None:
    f = tmp_path / "a.json"
    write_atomic(f, b"old")
    write_atomic(f, b"new")
    assert f.read_bytes() == b"new"

    class Boom(Exception):
        pass

    with pytest.raises(Boom), atomic_path(f) as tmp:
        tmp.write_bytes(b"half")
        raise Boom
    assert f.read_bytes() == b"new" and sorted(p.name for p in tmp_path.iterdir()) == ["a.json"]


def test_scan_and_truth_files_leave_no_temporary_behind(tmp_path: Path) -> None:
    f = tmp_path / "Scan_00001.e57"
    pts = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
    write_e57(f, [PosedScan.as_scanned(pts, [0.1, 0.2], f.stem)], durable=True)
    truth = ScanTruth(
        stamp_ns=1, scanner_pose=np.eye(4).tolist(), x=1, y=2, z=0, roll=0, pitch=0, yaw=0
    )
    write_truth(f, truth)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "Scan_00001.e57",
        "Scan_00001.truth.json",
    ]
    assert np.allclose(_read(f)[0], pts, atol=1e-5)
    assert read_truth(f) == truth


def test_snapshot_round_trip_restores_robot_and_noise(tmp_path: Path) -> None:
    layout, fld = load_field("spl")
    world = snapshot.fingerprint(layout, fld, WorldConfig())
    rng = np.random.default_rng(7)
    rng.normal(size=3)
    state = RobotState(x=1.5, y=2.5, yaw=0.3, v=0.2, w=-0.1, icr=0.01)
    path = snapshot.snapshot_path(tmp_path)
    snapshot.save(path, snapshot.take(world, "spl", 123_000, [(state, rng, None)]))
    expected = rng.normal(size=4)

    snap = snapshot.load(path, world)
    assert snap is not None and snap.sim_ns == 123_000
    rng2 = np.random.default_rng(0)
    assert snapshot.restore(snap, rng2) == state
    assert np.array_equal(rng2.normal(size=4), expected)


def test_snapshots_of_another_world_or_deployment_or_garbage_are_ignored(tmp_path: Path) -> None:
    layout, fld = load_field("spl")
    engr_layout, engr = load_field("engr")
    world = snapshot.fingerprint(layout, fld, WorldConfig())
    assert world != snapshot.fingerprint(engr_layout, engr, WorldConfig())
    assert world != snapshot.fingerprint(layout, fld, WorldConfig(seed=1))
    path = snapshot.snapshot_path(tmp_path)
    assert snapshot.load(path, world) is None  # none yet
    rng = np.random.default_rng(0)
    snapshot.save(path, snapshot.take(world, "spl", 5, [(RobotState(), rng, None)]))
    assert snapshot.load(path, "another world") is None
    assert snapshot.load(path, world, deployment="1@2") is None  # an earlier launcher's
    assert snapshot.load(path, world) is not None
    # a simulator told to stop leaves nothing to continue
    snapshot.save(path, snapshot.take(world, "spl", 5, [(RobotState(), rng, None)], closed=True))
    assert snapshot.load(path, world) is None
    path.write_bytes(b"{not json")
    assert snapshot.load(path, world) is None
    assert dataclasses.fields(RobotState)  # restore filters on these names
