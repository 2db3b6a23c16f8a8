from typing import Annotated, Literal

import msgspec

from common.battery import Pace
from common.messages.core import Positive, RobotName
from common.messages.nav import ARRIVAL_TOLERANCE_M, ArrivalTolerance
from common.messages.scan import ScanProfile


def _profile() -> ScanProfile:
    # 1/8 resolution at 2x quality: about a minute on a Focus S70 (scan_id is set per step)
    return ScanProfile(scan_id=1, resolution=8, quality=2)


class LanesConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Lane reservations with the robots sharing the field (:mod:`services.mission.lanes`,
    docs/fleet.md)."""

    peers: list[RobotName] = msgspec.field(default_factory=list)
    """The namespaces of the robots sharing the field, whose missions this one reserves
    lane segments with (none: this robot surveys alone, and reserves nothing)."""
    margin_m: Annotated[float, msgspec.Meta(ge=0, le=5)] = 0.3
    """How far beyond its body's reach the robot may stray from its route (the tracking
    error and the estimate's), reserved with it; with the body's reach it must stay under
    the parking distance (:data:`common.lanes.PARK_M`)."""
    retry_s: Positive = 1.0
    """How often a peer is asked again while the answer is to wait (the mission's clock;
    twice that after backing off)."""
    answer_timeout_s: Positive = 2.0
    """A peer silent this long (wall) has not answered."""


class MissionConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The survey supervisor. Times are on the service's clock (sim time in simulation).

    The battery (:mod:`services.mission.battery`, docs/mission-log.md): before each
    location the charge the base reports must cover it and the way back to the Origin,
    above the robot description's reserve, or the robot goes to the Origin and waits for
    a swap; the plan's time and swaps are estimated at ``pace``, the swaps themselves
    follow what the battery reports.
    """

    profile: ScanProfile = msgspec.field(default_factory=_profile)
    """The FARO scan profile; the scan id is set per location."""
    settle_s: Positive = 2.0
    """How long the robot must be still (|v| < ``still_speed``, |w| <
    ``still_turn``) and localized before a scan starts."""
    still_speed: Positive = 0.01
    """The speed under which the robot counts as still (m/s)."""
    still_turn: Positive = 0.01
    """The turn rate under which the robot counts as still (rad/s)."""
    scan_retries: Annotated[int, msgspec.Meta(ge=0, le=10)] = 2
    """Further attempts after a scanner error before the location is ``failed``."""
    scan_timeout_s: Positive = 1800.0
    """How long a scan may take before the attempt is given up."""
    blocked_retries: Annotated[int, msgspec.Meta(ge=0, le=10)] = 1
    """Route attempts after navigation reports blocked (or fails) before the location
    is ``skipped``."""
    route_time_s: Positive = 300.0
    """A route's time allowance: this plus its length at ``route_min_speed``, then it
    is given up."""
    route_min_speed: Positive = 0.05
    """The slowest a route's allowance counts on driving (m/s)."""
    settle_timeout_s: Positive = 900.0
    """How long the robot may take to stand still and localized before a scan."""
    arrival_tolerance_m: ArrivalTolerance = ARRIVAL_TOLERANCE_M
    """How far the pose estimate may be from the planned location before a scan starts
    (each route to a location carries it: navigation arrives within it or fails)."""
    scan_tolerance_m: Positive = 0.10
    """How far the estimate's mean over a scan may be from the planned location and the
    scan still count, while its spread stays within half ``arrival_tolerance_m``: the
    robot stands still through it, so what moves is the estimate under the crop. A stop
    this far off still sees every cell the plan covers (the planner's visibility:
    ``bench_planner``'s position tolerance in docs/results.md)."""
    position_retries: Annotated[int, msgspec.Meta(ge=0, le=10)] = 2
    """Drives to get within ``arrival_tolerance_m`` of the location."""
    lease_s: Annotated[float, msgspec.Meta(gt=0, le=3600)] = 2.0
    """The route lease navigation holds: renewed every quarter of it; without renewal the
    robot stops."""
    rpc_timeout_s: Positive = 5.0
    """Per call (wall time; in lockstep at least ``lockstep_deadline_s``)."""
    rpc_patience_s: Positive = 120.0
    """A service silent this long (wall; a restart takes seconds) fails the mission."""
    scanner_lost_s: Positive = 10.0
    """No new status from the scanner for this long during a scan: the attempt is given
    up (a scanner that restarted or hangs keeps its last "scanning" the newest held)."""
    nav_lost_s: Positive = 5.0
    """No new pose from navigation for this long during a scan: the attempt is given up
    (the pose over it is unknown)."""
    plan_timeout_s: Positive = 300.0
    """How long the plan may take to come from the planner."""
    scan_pose: Literal["end", "mean"] = "end"
    """The navigation pose a scan is recorded with: ``end``, the estimate at the scan's
    end (standing, the filter averages every fix since the robot stopped, so its last
    estimate has seen them all), or ``mean``, the mean over the scan (for a filter that
    forgets while standing, as the paper's profile does;
    :func:`services.mission.stats.scan_pose`)."""
    return_to_origin: bool = True
    """Drive back to the start corner at the end."""
    resume: bool = True
    """Resume the newest unfinished mission in the run folder when the service starts."""
    register_on_done: bool = True
    """Register the scans once the mission is done (``python -m services.register RUN_DIR
    --manifest M``, a child process at low priority, with the manifest's
    ``[services.register]`` options)."""
    traits_on_done: bool = True
    """Then, when registration succeeded, compute the per-plot traits (``python -m
    services.traits RUN_DIR --manifest M``, the same way, with the manifest's
    ``[services.traits]`` options, output in ``RUN_DIR/traits.log``; docs/traits.md)."""
    battery_stale_s: Positive = 10.0
    """No battery state for this long: the battery is not watched (said once in the
    mission log)."""
    swapped_at: Annotated[float, msgspec.Meta(gt=0, le=1)] = 0.9
    """The charge, as a fraction of full, that ends a wait for a swap."""
    origin_radius_m: ArrivalTolerance = 2.0
    """How near the Origin the robot is there: for a swap, and the arrival tolerance of
    the routes there (home, to a swap), which skip fine positioning (no scan is taken
    at the Origin)."""
    pace: Pace = msgspec.field(default_factory=Pace)
    """The speed along routes and the time at a location the plan's time and its battery
    swaps are estimated with."""
    share: Annotated[int, msgspec.Meta(ge=0, le=64)] = 0
    """This robot's share (1..N) of a plan split between N robots (``phenorover plan
    --robots N``); 0 surveys the whole plan (a plan for one robot parked by its
    locations, ``--home near``, is its one share) and refuses a split one
    (docs/fleet.md)."""
    lanes: LanesConfig = msgspec.field(default_factory=LanesConfig)
    """The lane reservations with the robots sharing the field."""
