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
