from typing import Annotated, Literal

import msgspec

from common.battery import Pace
from common.messages.core import Positive, RobotName
from common.messages.nav import ARRIVAL_TOLERANCE_M
from common.messages.scan import ScanProfile


def _profile() -> ScanProfile:
    # 1/8 resolution at 2x quality: about a minute on a Focus S70 (scan_id is set per step)
    return ScanProfile(scan_id=1, resolution=8, quality=2)


class LanesConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Lane reservations with the robots sharing the field (:mod:`services.mission.lanes`):
    ``peers`` their namespaces (none: this robot surveys alone, and reserves nothing).
    ``margin_m``: how far beyond its body's reach a robot may stray from its route (the
    tracking error and the estimate's), reserved with it; with the body's reach it must
    stay under the parking distance (:data:`common.lanes.PARK_M`). A peer is asked
    every ``retry_s`` (the mission's clock; twice that after backing off) while the
    answer is to wait, and one silent for ``answer_timeout_s`` (wall) has not answered."""

    peers: list[RobotName] = msgspec.field(default_factory=list)
    margin_m: Annotated[float, msgspec.Meta(ge=0, le=5)] = 0.3
    retry_s: Positive = 1.0
    answer_timeout_s: Positive = 2.0


class MissionConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The survey supervisor. Times are on the service's clock (sim time in simulation).

    ``settle_s``: how long the robot must be still (|v| < ``still_speed``, |w| <
    ``still_turn``) and localized before a scan starts. ``scan_retries``: further
    attempts after a scanner error before the location is marked failed.
    ``blocked_retries``: route attempts after navigation reports blocked (or fails)
    before the location is skipped. ``arrival_tolerance_m``: how far the pose estimate
    may be from the planned location before a scan starts (each route to a location
    carries it: navigation arrives within it or fails); ``position_retries`` drives to
    get there. ``scan_tolerance_m``: how far the estimate's mean over the scan may be
    and the scan still count: the robot
    stands still through it (its spread must stay within half the arrival
    tolerance), so what moves is the estimate under the crop, and a stop this far off
    still sees every cell the plan covers (the planner's visibility: ``bench_planner``'s
    position tolerance in docs/results.md). ``lease_s``: the route lease navigation
    holds (renewed every quarter of it; without renewal the robot stops). A route gets
    ``route_time_s`` plus its length at ``route_min_speed`` before it is given up.
    ``rpc_timeout_s`` (wall) per call; a service silent for ``rpc_patience_s`` (wall,
    a restart takes seconds) fails the mission. ``scanner_lost_s``: no status for the
    scan being taken for this long and the attempt is lost (the scanner restarted).
    ``scan_pose``: the navigation pose a scan is recorded with, ``end`` (the estimate
    at the scan's end: standing, our filter averages every fix since the robot
    stopped) or ``mean`` (the mean over the scan, for a filter that forgets while
    standing; :func:`services.mission.stats.scan_pose`).
    ``resume``: pick up an unfinished mission found in the run
    folder when the service starts. ``register_on_done``: register the scans (``python
    -m services.register RUN_DIR --manifest M``, a child process at low priority, with
    the manifest's ``[services.register]`` options) once the mission is done.
    ``traits_on_done``: then, when registration succeeded, compute the per-plot traits
    (``python -m services.traits RUN_DIR --manifest M``, the same way, with the
    manifest's ``[services.traits]`` options; see docs/traits.md).

    The battery (:mod:`services.mission.battery`): before each location the charge
    the base reports must cover it and the way back to the Origin, above the robot
    description's reserve, or the robot goes to the Origin (within
    ``origin_radius_m`` of it is there) and waits until the base reports at least
    ``swapped_at`` of a full charge. With no battery state for ``battery_stale_s`` the
    battery is not watched (said once in the mission log). ``pace``: the speed along
    routes and the time at a location the plan's time and swaps are estimated with
    (:class:`common.battery.Pace`); the swaps themselves follow what the battery
    reports.

    ``share``: this robot's share (1..N) of a plan split between N robots
    (``phenorover plan --robots N``); 0, alone, surveys the whole plan (the one share
    of a plan for one robot, ``--home near``), and a plan split between several is
    refused. ``lanes``: the reservations with the robots sharing the field.
    """

    profile: ScanProfile = msgspec.field(default_factory=_profile)
    settle_s: Positive = 2.0
    still_speed: Positive = 0.01
    still_turn: Positive = 0.01
    scan_retries: Annotated[int, msgspec.Meta(ge=0, le=10)] = 2
    scan_timeout_s: Positive = 1800.0
    blocked_retries: Annotated[int, msgspec.Meta(ge=0, le=10)] = 1
    route_time_s: Positive = 300.0
    route_min_speed: Positive = 0.05
    settle_timeout_s: Positive = 900.0
    arrival_tolerance_m: Positive = ARRIVAL_TOLERANCE_M
    scan_tolerance_m: Positive = 0.10
    position_retries: Annotated[int, msgspec.Meta(ge=0, le=10)] = 2
    lease_s: Annotated[float, msgspec.Meta(gt=0, le=3600)] = 2.0
    rpc_timeout_s: Positive = 5.0
    rpc_patience_s: Positive = 120.0
    scanner_lost_s: Positive = 10.0
    nav_lost_s: Positive = 5.0
    plan_timeout_s: Positive = 300.0
    scan_pose: Literal["end", "mean"] = "end"
    return_to_origin: bool = True
    resume: bool = True
    register_on_done: bool = True
    traits_on_done: bool = True
    battery_stale_s: Positive = 10.0
    swapped_at: Annotated[float, msgspec.Meta(gt=0, le=1)] = 0.9
    origin_radius_m: Positive = 2.0
    pace: Pace = msgspec.field(default_factory=Pace)
    share: Annotated[int, msgspec.Meta(ge=0, le=64)] = 0
    lanes: LanesConfig = msgspec.field(default_factory=LanesConfig)
