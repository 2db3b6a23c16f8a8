"""A whole survey's pace for ``bench_survey``: field time per location against its
physical reference (:mod:`phenorover.eval.pace`), and the poses its scans were placed
with against the simulator's truth."""

from __future__ import annotations

import statistics
from collections.abc import Callable
from pathlib import Path
from typing import Any

from common.config import decode_section, load_manifest
from common.robot import load_robot
from phenorover.cpu import read_use
from phenorover.eval.pace import pace, scan_pose_errors, true_stops_cm
from phenorover.eval.results import Goal
from services import SERVICES
from services.mission.config import MissionConfig
from services.nav.config import NavConfig

# the acceptance of the pace issue: field time within 1.5 x the physical reference;
# scan poses within 1.0 cm and a heading no worse than bench_nav's 0.165 deg
PACE = Goal(
    "<=",
    1.5,
    "the settles and positioning moves at each location (each arrival's moves are in "
    "the mission log), or a slower cruise than the reference's",
)
POSE = Goal("<=", 1.0, "a longer stand at each location (the estimate averages the fixes)")
# the stated position tolerance: the follower works to 2 cm along the leg and 3 cm
# across, inside the mission's 5 cm arrival check; by the planner's visibility a stop
# 30 cm off loses no covered cell (bench_planner)
TRUE_STOP = Goal(
    "<=",
    100 * MissionConfig().arrival_tolerance_m,
    "the follower's tolerances (fine_tolerance_m, reapproach_tolerance_m), or the "
    "estimate it stops on: each arrival's moves are in the mission log",
)
HEADING = Goal(
    "<=",
    0.165,
    "the compass under the crop reads about 2 deg a fix, correlated over seconds; a "
    "scan's heading is what the stand averages: a longer stand, or the heading carried "
    "from the legs by the gyro (a smoother), or taken from the registration",
)


def reference_model(manifest: Path) -> tuple[float, float, float, float]:
    """(cruise speed m/s, turn rate rad/s, turn acceleration rad/s^2, settle s) of the
    physical reference: the follower's cruise speed in ``manifest``; the turns at the
    robot's own limits (its description), not the follower's; the mission's settle
    before a scan. Raises ConfigError on a bad manifest or robot description."""
    m = load_manifest(manifest)
    nav = decode_section(m.services.get("nav", {}), NavConfig, "[services.nav]")
    mission = decode_section(m.services.get("mission", {}), MissionConfig, "[services.mission]")
    limits = load_robot(m.robot).limits
    return (nav.follower.max_speed, limits.max_turn_rate, limits.max_turn_accel, mission.settle_s)


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
    stops = true_stops_cm(run_dir)
    out["true_stops_cm"] = stops
    out["true_stop_cm"] = statistics.mean(stops) if stops else None
    use = read_use(run_dir / "cpu.json")
    if use is not None:
        rates = use.per_sim_s()
        out |= {f"cpu_{name}": rate for name, rate in rates.items()}
        out["cpu_total"] = sum(rates.values()) if rates else None
        out["survey_wall_s"] = use.wall_s
    if errors:
        out["scan_pose_cm"] = statistics.mean(h for h, _ in errors)
        out["scan_heading_deg"] = statistics.mean(abs(d) for _, d in errors)
    return out


def pace_figures(
    fig: Callable[..., None], baseline: bool, model: tuple[float, ...], runs: list[dict[str, Any]]
) -> None:
    """The figures of ``runs`` (:func:`survey_pace` of each), through ``bench_survey``'s
    ``fig(label, key, unit, note, **kw)``."""
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
    cpu = "CPU seconds per simulated second over the survey (the launcher's reading of /proc)"
    fig(cpu + ", all services", "cpu_total", "s/s")
    for name in [n for n in SERVICES if any(f"cpu_{n}" in r for r in runs)]:
        fig(f"{cpu}: {name}", f"cpu_{name}", "s/s")
    fig("wall time of the survey itself (mission started to done)", "survey_wall_s", "s")
    stops = [v for r in runs for v in r.get("true_stops_cm", [])]
    fig(
        "true stop at each scan against its planned location, mean",
        "true_stop_cm",
        "cm",
        note=f"{len(stops)} scans, max {max(stops):.2f} cm" if stops else "",
        goal=None if baseline else TRUE_STOP,
        headline=True,
    )
