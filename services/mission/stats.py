"""Pose statistics over a scan. Pure."""

from __future__ import annotations

import math

from common.messages.nav import PoseEstimate


def pose_stats(poses: list[PoseEstimate]) -> dict[str, float]:
    """Mean and SD of x, y, z and heading (circular) over a scan."""
    n = max(len(poses), 1)
    out: dict[str, float] = {}
    for k in ("x", "y", "z"):
        v = [getattr(p, k) for p in poses] or [math.nan]
        m = sum(v) / n
        out[f"mean_{k}"] = m
        out[f"sd_{k}"] = math.sqrt(sum((a - m) ** 2 for a in v) / n)
    c = sum(math.cos(p.yaw) for p in poses) / n
    s = sum(math.sin(p.yaw) for p in poses) / n
    out["mean_yaw"] = math.atan2(s, c)
    out["sd_yaw"] = math.sqrt(max(0.0, -2.0 * math.log(max(math.hypot(c, s), 1e-12))))
    return out


def tilt_stats(poses: list[PoseEstimate]) -> dict[str, float | None]:
    """The mean tilt navigation put the antennas through over a scan (``nav_roll``,
    ``nav_pitch``, rad); None unless every pose was tilted, since a scan mixing both
    cannot be undone by one figure."""
    if not poses or not all(p.tilted for p in poses):
        return {"nav_roll": None, "nav_pitch": None}
    n = len(poses)
    roll, pitch = sum(p.roll for p in poses) / n, sum(p.pitch for p in poses) / n
    return {"nav_roll": roll, "nav_pitch": pitch}


def scan_pose(poses: list[PoseEstimate], how: str = "end") -> dict[str, float]:
    """The navigation pose a scan is placed with (``pose_x``, ``pose_y``, ``pose_z``,
    ``pose_yaw``): ``end``, the last of ``poses`` (the estimate at the scan's end), or
    ``mean``, their mean. A standing robot's filter (zero-velocity updates, no
    process noise) is the running average of every fix since it stopped, so its last
    estimate has seen them all, where the mean of its estimates weighs the early, less
    informed ones as much; a filter that forgets while standing (the paper's, with
    static process noise) is better averaged. Raises ValueError on no poses."""
    if not poses:
        raise ValueError("no poses over the scan")
    if how == "end":
        last = poses[-1]
        return {"pose_x": last.x, "pose_y": last.y, "pose_z": last.z, "pose_yaw": last.yaw}
    if how == "mean":
        st = pose_stats(poses)
        return {f"pose_{k}": st[f"mean_{k}"] for k in ("x", "y", "z", "yaw")}
    raise ValueError(f"scan_pose: {how!r} is neither 'end' nor 'mean'")
