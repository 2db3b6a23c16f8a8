"""A whole survey's pace for ``bench_survey``: field time per location against its
physical reference (:mod:`phenorover.eval.pace`), and the poses its scans were placed
with against the simulator's truth."""

from __future__ import annotations

import statistics
from collections.abc import Callable
from pathlib import Path
from typing import Any

from common.config import read_toml
from phenorover.eval.pace import pace, scan_pose_errors
from phenorover.eval.results import Goal
from services.mission.config import MissionConfig
from services.nav.follower_config import FollowerConfig

# the acceptance of the pace issue: field time within 1.5 x the physical reference;
# scan poses within 1.0 cm and a heading no worse than bench_nav's 0.165 deg
PACE = Goal(
    "<=",
    1.5,
    "the settles and positioning moves at each location (each arrival's moves are in "
    "the mission log), or a slower cruise than the reference's",
)
POSE = Goal("<=", 1.0, "a longer stand at each location (the estimate averages the fixes)")
HEADING = Goal(
    "<=",
    0.165,
    "the compass under the crop reads about 2 deg a fix, correlated over seconds; a "
    "scan's heading is what the stand averages: a longer stand, or the heading carried "
    "from the legs by the gyro (a smoother), or taken from the registration",
)


def _section(manifest: Path, name: str) -> dict[str, Any]:
    services = read_toml(manifest).get("services", {})
    return dict(services.get(name, {}))


def reference_model(manifest: Path) -> tuple[float, float, float, float]:
    """(cruise speed m/s, turn rate rad/s, turn acceleration rad/s^2, settle s): the
    follower's and the mission's settings in ``manifest``, their defaults elsewhere."""
    f = FollowerConfig()
    over = _section(manifest, "nav").get("follower", {})
    settle = _section(manifest, "mission").get("settle_s", MissionConfig().settle_s)
    return (
        float(over.get("max_speed", f.max_speed)),
        float(over.get("max_turn_rate", f.max_turn_rate)),
        float(over.get("max_turn_accel", f.max_turn_accel)),
        float(settle),
    )


def survey_pace(run_dir: Path, model: tuple[float, float, float, float]) -> dict[str, Any]:
    """The pace figures of the survey in ``run_dir`` (none when it never finished)."""
    p = pace(run_dir, *model)
    errors = scan_pose_errors(run_dir)
    out: dict[str, Any] = {}
    if p is not None:
        out |= {
            "field_s": p.field_s,
            "reference_s": p.reference_s,
            "pace_ratio": p.ratio,
            "scanning_s": p.scanning_s,
        }
    if errors:
        out["scan_pose_cm"] = statistics.mean(h for h, _ in errors)
        out["scan_heading_deg"] = statistics.mean(abs(d) for _, d in errors)
    return out


def pace_figures(fig: Callable[..., None], baseline: bool, model: tuple[float, ...]) -> None:
    """The figures, through ``bench_survey``'s ``fig(label, key, unit, note, **kw)``."""
    speed, rate, accel, settle = model
    ref = (
        f"the planned route at {speed:g} m/s, each turn in place at {rate:g} rad/s "
        f"({accel:g} rad/s^2), a {settle:g} s settle per location"
    )
    fig("field time per location, the scans excluded", "field_s", "s", headline=True)
    fig("its physical reference per location", "reference_s", "s", note=ref)
    fig(
        "field time per location against its physical reference",
        "pace_ratio",
        "x",
        goal=None if baseline else PACE,
    )
    fig("scanning time per location", "scanning_s", "s")
    fig(
        "scan poses (navigation) against the truth: horizontal, mean",
        "scan_pose_cm",
        "cm",
        goal=None if baseline else POSE,
    )
    fig(
        "scan poses (navigation) against the truth: heading, mean magnitude",
        "scan_heading_deg",
        "deg",
        goal=None if baseline else HEADING,
    )
