"""Point clouds for the dashboard: a finished scan placed at its navigation pose, and
the registered cloud, both subsampled. Pure file -> array functions; the service runs
them off its logging loop.

Raises CloudError (one line naming the file) on anything unreadable: a dashboard on
another machine than the scanner's storage simply has no scan files to show.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import numpy.typing as npt

from common.messages.nav import PoseEstimate
from common.pointcloud import CloudIOError, PosedScan, read_e57
from common.poses import F64, apply, scanner_pose
from common.robot import ScannerMount


class CloudError(ValueError):
    """A cloud file that cannot be read."""


def subsample(points: F64, n: int, seed: int = 0) -> F64:
    """At most ``n`` of ``points`` (N, 3), drawn without replacement, order kept."""
    if len(points) <= n:
        return points
    keep = np.sort(np.random.default_rng(seed).choice(len(points), size=n, replace=False))
    out: F64 = points[keep]
    return out


def _finite(points: npt.NDArray[np.float64]) -> F64:
    out: F64 = points[np.all(np.isfinite(points), axis=1)]
    return out


def _scans(path: str | Path) -> list[PosedScan]:
    """The scans of E57 ``path``, at least one; raises CloudError."""
    try:
        scans = read_e57(path)
    except CloudIOError as exc:
        raise CloudError(str(exc)) from None
    if not scans:
        raise CloudError(f"{path}: no scan in the file")
    return scans


def scan_in_field(
    path: str | Path,
    pose: PoseEstimate,
    pitch: float,
    roll: float,
    mount: ScannerMount,
    n: int,
) -> F64:
    """The first scan of E57 ``path`` (points in the scanner frame), subsampled to
    ``n`` points and placed in the field frame with the navigation pose and the
    inclinometer's pitch and roll (paper eq. 1, the scanner at ``mount`` on the robot)."""
    scans = _scans(path)
    vals = (pose.x, pose.y, pose.z, pose.yaw, pitch, roll)
    if not all(math.isfinite(v) for v in vals):
        raise CloudError(f"{path}: the pose to place it at is not finite: {vals}")
    m = scanner_pose(pose.x, pose.y, pose.z, pose.yaw, pitch, roll, mount.xyz, mount.yaw_rad)
    return apply(m, subsample(_finite(scans[0].points), n))


def registered(path: str | Path, n: int) -> F64:
    """The registered cloud in the field frame, subsampled to ``n`` points: a LAZ
    (already merged in the field frame) or a multi-scan E57 with each scan's pose."""
    p = Path(path)
    if p.suffix.lower() in (".laz", ".las"):
        import laspy

        try:
            las = laspy.read(str(p))
        except Exception as exc:  # laspy raises its own types and OSError
            raise CloudError(f"{p}: cannot read LAS/LAZ: {exc}") from None
        pts = np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])
        return subsample(_finite(pts.astype(np.float64)), n)
    scans = _scans(p)
    per = max(n // len(scans), 1)
    return np.vstack([apply(s.pose, subsample(_finite(s.points), per)) for s in scans])


def find_registered(folder: Path, globs: list[str]) -> Path | None:
    """The newest file matching the first of ``globs`` that matches anything in
    ``folder``, once it has stopped changing for a second (a writer may be busy)."""
    import time

    for g in globs:
        # a hidden name is a file being written (common.files.atomic_path)
        found = [p for p in folder.glob(g) if p.is_file() and not p.name.startswith(".")]
        if found:
            newest = max(found, key=lambda p: p.stat().st_mtime)
            return newest if time.time() - newest.stat().st_mtime > 1.0 else None
    return None
