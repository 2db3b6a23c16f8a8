"""The pose a scan is recorded with (services/mission/stats.py)."""

from __future__ import annotations

import math

import pytest

from common.messages.nav import PoseEstimate
from services.mission.stats import pose_stats, scan_pose


def running_average(n: int) -> list[PoseEstimate]:
    """A standing robot's estimates: each the mean of the fixes so far, which read
    x = 1, 2, ..., n (true x unknown); yaw likewise in milliradians about pi."""
    out = []
    for k in range(1, n + 1):
        mean = (k + 1) / 2
        out.append(PoseEstimate(x=mean, y=0.0, z=0.5, yaw=math.pi - 1e-3 * mean))
    return out


def test_the_end_is_the_last_estimate_and_the_mean_the_means() -> None:
    poses = running_average(9)
    end = scan_pose(poses)
    assert end == pytest.approx(
        {"pose_x": 5.0, "pose_y": 0.0, "pose_z": 0.5, "pose_yaw": poses[-1].yaw}
    )
    mean = scan_pose(poses, "mean")
    st = pose_stats(poses)
    assert mean["pose_x"] == pytest.approx(st["mean_x"]) and mean["pose_x"] < end["pose_x"]
    # the heading's mean is circular: estimates on both sides of +-pi average to pi
    wrapped = [
        PoseEstimate(x=0.0, y=0.0, yaw=math.pi - 0.01),
        PoseEstimate(x=0.0, y=0.0, yaw=-math.pi + 0.01),
    ]
    assert abs(abs(scan_pose(wrapped, "mean")["pose_yaw"]) - math.pi) < 1e-9


def test_no_poses_or_an_unknown_rule_is_refused() -> None:
    with pytest.raises(ValueError, match="no poses"):
        scan_pose([])
    with pytest.raises(ValueError, match="neither 'end' nor 'mean'"):
        scan_pose(running_average(2), "median")
