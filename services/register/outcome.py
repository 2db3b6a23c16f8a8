"""What a registration gives (:func:`services.register.pipeline.register`): the
report, per scan, per pair and per method scored against the target-based
reference, and the poses of every method with the scans themselves for the
outputs."""

from __future__ import annotations

import dataclasses

import msgspec
import numpy as np
import numpy.typing as npt

from common.pointcloud import PosedScan
from common.poses import F64
from services.register.metrics import CloudDistance, OverlapStats, PointStats, TargetStats

Pose = list[list[float]]


class ScanReport(msgspec.Struct, frozen=True, kw_only=True):
    """Per scan: points read and kept after downsampling, spheres found (their fit
    RMS, m), targets matched and whether they fixed the reference pose, and the poses
    (4x4 field <- scanner, row-major lists); ``c2c_without_targets_pose`` when the
    report has that method. ``file``: the scan file registered. ``sphere_centres``:
    the centres found (scanner frame, m), ``sphere_targets`` the target each was
    matched to (-1: none), so targets can be scored from the report alone."""

    name: str
    points: int
    downsampled: int
    spheres: int
    sphere_rms: list[float]
    targets: int
    target_solved: bool
    nav_pose: Pose
    c2c_pose: Pose
    target_pose: Pose
    file: str = ""
    sphere_centres: list[tuple[float, float, float]] = msgspec.field(default_factory=list)
    sphere_targets: list[int] = msgspec.field(default_factory=list)
    c2c_without_targets_pose: Pose | None = None


class PairReport(msgspec.Struct, frozen=True, kw_only=True):
    """One pairwise GICP (scan indices, overlap share, RMSE in m, kept or why not)."""

    i: int
    j: int
    overlap: float
    rmse: float
    kept: bool
    reason: str


class MethodReport(msgspec.Struct, frozen=True, kw_only=True):
    """A registration scored against the target-based reference, and its overlap
    residuals (SCENE's scan point statistics; need no reference)."""

    targets_vs_reference: TargetStats
    points_vs_reference: PointStats | None
    cloud_vs_reference: CloudDistance | None
    overlap: OverlapStats | None = None


class RegistrationReport(msgspec.Struct, frozen=True, kw_only=True):
    """The registration report: per scan, per pair, per method, and timings (s);
    ``time_s`` is the registration proper (read, downsample, spheres, C2C, targets).
    ``c2c`` is navigation + C2C with the spheres in the pose graph when the refine
    config uses them; ``c2c_without_targets`` then gives the clouds alone."""

    scans: list[ScanReport]
    pairs: list[PairReport]
    navigation: MethodReport
    c2c: MethodReport
    target_based: MethodReport
    timings: dict[str, float]
    time_s: float
    c2c_without_targets: MethodReport | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class Registration:
    """The report plus per-scan poses of every method, the scans themselves (scanner
    frame, with the C2C pose) for writing outputs, and per scan the sphere centres
    found (scanner frame) with their target labels (-1: unmatched).
    ``plain_poses``: the C2C poses without the spheres when the report has them."""

    report: RegistrationReport
    nav_poses: list[F64]
    c2c_poses: list[F64]
    target_poses: list[F64]
    scans: list[PosedScan]
    centres: list[F64]
    labels: list[npt.NDArray[np.int64]]
    plain_poses: list[F64] | None = None
