"""A robot standing still before a scan, as the mission's survey waits for it."""

from __future__ import annotations

from common.clock import NS
from common.messages.nav import PoseEstimate
from services.mission.port import SurveyPort


def settle(sv: SurveyPort) -> PoseEstimate | None:
    """Wait until the robot has been localized throughout the last ``settle_s``
    and its mean speed and turn rate over them are below the still thresholds
    (the mean, not every sample: the estimate's turn rate carries the encoders'
    noise). Returns the newest pose, or None after ``settle_timeout_s``."""
    window: list[PoseEstimate] = []
    t0 = sv.now()
    warned = silent = False
    while True:
        t0 += sv.wait(0.1)
        now = sv.now()
        if (now - t0) / NS > sv.cfg.settle_timeout_s:
            return None
        p = sv.pose.get()
        if p is None or (window and p.stamp_ns <= window[-1].stamp_ns):
            # nothing new: a navigation that hangs is not a robot standing still
            age = sv.pose_age_s()
            if age > sv.cfg.nav_lost_s and not silent:
                sv.event("warning", f"no pose from navigation for {age:.0f} s: waiting")
            silent = age > sv.cfg.nav_lost_s
            continue
        if not p.localized:
            if not warned:
                sv.event("warning", "localization lost before a scan: waiting")
                warned = True
            window.clear()
            continue
        window.append(p)
        window = [q for q in window if (p.stamp_ns - q.stamp_ns) / NS <= sv.cfg.settle_s]
        if (p.stamp_ns - window[0].stamp_ns) / NS < 0.9 * sv.cfg.settle_s:
            continue
        v = sum(q.v for q in window) / len(window)
        w = sum(q.w for q in window) / len(window)
        if abs(v) < sv.cfg.still_speed and abs(w) < sv.cfg.still_turn:
            return p
