"""The route follower's settings (``[services.nav.follower]``)."""

from __future__ import annotations

from typing import Annotated

import msgspec

from common.messages.core import Positive


class FollowerConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Speeds within the Husky's limits. The paper's look-ahead was 1 m and it drove
    off a corner once within its 2 deg heading tolerance; ``lookahead_m`` 0.6 and
    ``align_tolerance_deg`` 0.5 close the corner turn's sideways shift and heading
    error about twice as fast (pure pursuit settles a lateral offset over two to
    three look-aheads of travel), while a centimetre of estimate noise still steers
    by only a degree. Cruise at ``max_speed`` 0.5 m/s, the paper's method's own
    speed: accuracy is won by control (the turn toward the line after a corner, the
    pose predicted over the drivetrain's lag), not by crawling.

    At a scan location what counts is that the robot stands still while the scanner
    runs and that its pose over the scan is known (the estimate averages the fixes
    while it stands), not that it stands on the planned point to the millimetre: by
    the planner's own visibility, stops up to 30 cm off their marks see every cell
    the plan covers (``phenorover.eval.tolerance``). So the fine phase works to
    centimetres (``fine_tolerance_m`` along the leg, ``reapproach_tolerance_m``
    across it, inside the mission's 5 cm arrival check and the lane's clearance)
    and settles only as long as judging that takes."""

    lookahead_m: Positive = 0.6
    # an in-place turn toward a leg ends within this of the leg's heading
    align_tolerance_deg: Positive = 0.5
    # on the route's last leg, toward the scan location: pure pursuit closes a
    # lateral offset over about one look-ahead of travel, and the corner turn before
    # it shifts the robot sideways by centimetres
    final_lookahead_m: Positive = 0.5
    # pure pursuit steers from the pose this far ahead under the last command (the
    # drivetrain's lag, about 0.15 s, and the control period): a command acts on the
    # robot as it will be, not as it was, which keeps the loop damped at speed
    predict_s: Annotated[float, msgspec.Meta(ge=0, le=1)] = 0.15
    max_speed: Positive = 0.5
    max_accel: Positive = 0.5
    # a turn in place runs at up to ``max_turn_rate``, slowing as it nears its heading
    # at the lowest of ``rotate_gain`` times the error and the rate it can still brake
    # from at ``turn_braking`` of ``max_turn_accel`` (a margin for the drivetrain's
    # lag): the turn takes about its physical time, where a proportional law alone
    # spends seconds in its exponential tail (tests/nav/test_follower.py holds both)
    max_turn_rate: Positive = 1.2
    max_turn_accel: Positive = 2.0
    rotate_gain: Positive = 3.0
    turn_braking: Annotated[float, msgspec.Meta(gt=0, le=1)] = 0.5
    min_turn_rate: Positive = 0.04
    heading_tolerance_deg: Positive = 2.0
    goal_tolerance_m: Positive = 0.02
    min_speed: Positive = 0.03
    obstacle_timeout_s: Positive = 30.0
    # fine positioning at the route's end (the scan location)
    fine: bool = True
    fine_tolerance_m: Positive = 0.02
    # trims to a planned heading (a scan location has none) stop this close to it, or
    # within the filter's heading SD when that is larger
    fine_heading_tolerance_deg: Positive = 0.5
    # stand at least this long on arrival (the drivetrain's lag, and the estimate
    # taking in that the robot stands), and this long after a creep or trim
    fine_settle_s: Positive = 1.0
    fine_resettle_s: Positive = 1.0
    # ... and on arrival until the estimate's position SD (its larger axis, the
    # filter's own, which counts the fixes' correlation over seconds) is below this,
    # at most ``fine_settle_max_s``: a centimetre judges a 2-3 cm tolerance
    fine_settle_sd_m: Positive = 0.01
    fine_settle_max_s: Positive = 10.0
    creep_speed: Positive = 0.03
    creep_turn_rate: Positive = 0.02
    # how long a creep command takes to show in the pose (drivetrain lag plus the
    # estimate's): the creep stops this much early so it does not overshoot
    creep_latency_s: Positive = 0.2
    # at most this many creeps (re-approaches included) and as many heading trims
    fine_moves: Annotated[int, msgspec.Meta(ge=0)] = 6
    # a sideways offset cannot be crept away by a skid-steer robot: it backs up along
    # the leg (at most the leg's length) and comes in again slowly, so that its pose
    # estimate, settled while standing, is carried by odometry rather than pulled by
    # each moving fix
    reapproach_m: Positive = 0.8
    reapproach_speed: Positive = 0.1
    reapproaches: Annotated[int, msgspec.Meta(ge=0)] = 2
    reapproach_tolerance_m: Positive = 0.03
    # arrival is declared only within this angle of the route's planned heading (and
    # within the route's own distance, ``FollowRoute.arrival_tolerance_m``); else the
    # route fails: a scan must never be taken where the robot merely stopped. It is
    # its own setting, not the in-place turn's ``heading_tolerance_deg``: a last leg
    # without a final turn ends at the angle pure pursuit steered to close a sideways
    # offset
    arrival_heading_tolerance_deg: Annotated[float, msgspec.Meta(gt=0, le=180)] = 2.0
    # a route sent with ``join`` starts on the first leg passing this close to the
    # robot (lanes are 1.8 m apart or more, so a neighbouring lane never qualifies)
    join_distance_m: Positive = 0.5
