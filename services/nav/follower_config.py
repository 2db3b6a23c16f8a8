"""The route follower's settings (``[services.nav.follower]``)."""

from __future__ import annotations

from typing import Annotated

import msgspec

from common.messages.core import NonNegative, Positive


class FollowerConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Speeds within the Husky's limits. The paper's look-ahead was 1 m and it drove
    off a corner once within its 2 deg heading tolerance. Here the corner's turn holds
    the robot on the next leg's line as it turns (``turn_hold_gain``), and
    ``align_tolerance_deg`` 0.5 leaves it little heading error to drive off with.
    ``lookahead_m`` 0.4: pure pursuit holds a heading error of the estimate as a
    sideways offset of look-ahead times that error, and closes the slip of the soil
    over a look-ahead or two of travel; a shorter one steers on the position's
    noise. Cruise at ``max_speed`` 0.5 m/s, the paper's method's own speed: accuracy
    is won by control (the turn held on the line, the pose predicted over the
    drivetrain's lag), not by crawling.

    At a scan location what counts is that the robot stands still while the scanner
    runs and that its pose over the scan is known (the estimate averages the fixes
    while it stands), not that it stands on the planned point to the millimetre: by
    the planner's own visibility, stops up to 30 cm off their marks see every cell
    the plan covers (``phenorover.eval.tolerance``). So the fine phase works to
    centimetres (``fine_tolerance_m`` along the leg, ``reapproach_tolerance_m``
    across it, inside the mission's 5 cm arrival check and the lane's clearance)
    and settles only as long as judging that takes.

    A turn in place runs at up to ``max_turn_rate``, slowing as it nears its heading at
    the lowest of ``rotate_gain`` times the error and the rate it can still brake from
    at ``turn_braking`` of ``max_turn_accel`` (a margin for the drivetrain's lag): the
    turn takes about its physical time, where a proportional law alone spends seconds in
    its exponential tail (tests/nav/test_follower.py holds both)."""

    lookahead_m: Positive = 0.4
    """Pure pursuit's look-ahead (m)."""
    align_tolerance_deg: Positive = 0.5
    """An in-place turn toward a leg ends within this of the leg's heading."""
    final_lookahead_m: Positive = 0.5
    """The look-ahead on the route's last leg, toward the scan location: pure pursuit
    closes a lateral offset over about one look-ahead of travel, and the corner turn
    before it shifts the robot sideways by centimetres."""
    predict_s: Annotated[float, msgspec.Meta(ge=0, le=1)] = 0.15
    """Pure pursuit steers from the pose this far ahead under the last command (the
    drivetrain's lag, about 0.15 s, and the control period): a command acts on the
    robot as it will be, not as it was, which keeps the loop damped at speed."""
    max_speed: Positive = 0.5
    """Cruise speed (m/s); at most the robot description's ``[limits]``."""
    max_accel: Positive = 0.5
    """Acceleration limit (m/s²); at most the robot description's ``[limits]``."""
    max_turn_rate: Positive = 1.2
    """The fastest turn in place (rad/s); at most the robot description's ``[limits]``."""
    max_turn_accel: Positive = 2.0
    """Turn acceleration limit (rad/s²); at most the robot description's ``[limits]``."""
    rotate_gain: Positive = 3.0
    """A turn in place slows near its heading to at most this times the error (1/s)."""
    turn_braking: Annotated[float, msgspec.Meta(gt=0, le=1)] = 0.5
    """The share of ``max_turn_accel`` a turn in place plans to brake with."""
    min_turn_rate: Positive = 0.04
    """The slowest a turn in place is commanded (rad/s)."""
    turn_hold_gain: NonNegative = 3.0
    """While it turns onto a leg, the robot drives along its heading to close its offset
    from the leg's line at this rate (1/s; :func:`services.nav.turns.line_hold`). 0
    turns strictly in place."""
    turn_hold_speed: Positive = 0.15
    """The fastest that drive (m/s)."""
    turn_hold_max_m: Positive = 0.3
    """No such drive further than this off the leg's line (m)."""
    heading_tolerance_deg: Positive = 2.0
    """A heading error beyond this is turned out in place (toward a leg's or a planned
    heading) before the robot drives or arrives."""
    goal_tolerance_m: Positive = 0.02
    """A leg is done this close to its end (m)."""
    min_speed: Positive = 0.03
    """The slowest the robot is commanded while driving a leg (m/s)."""
    obstacle_timeout_s: Positive = 30.0
    """An obstacle in the way this long fails the route as blocked."""
    fine: bool = True
    """Fine positioning at the route's end (the scan location)."""
    fine_tolerance_m: Positive = 0.02
    """Fine positioning works along the leg to this distance from the location (m)."""
    fine_heading_tolerance_deg: Positive = 0.5
    """Trims to a planned heading (a scan location has none) stop this close to it, or
    within the filter's heading SD when that is larger."""
    fine_settle_s: Positive = 1.0
    """Stand at least this long on arrival (the drivetrain's lag, and the estimate
    taking in that the robot stands)."""
    fine_resettle_s: Positive = 1.0
    """Stand this long after a creep or trim."""
    fine_settle_sd_m: Positive = 0.01
    """On arrival, stand until the estimate's position SD (its larger axis, the filter's
    own, which counts the fixes' correlation over seconds) is below this, at most
    ``fine_settle_max_s``: a centimetre judges a 2-3 cm tolerance."""
    fine_settle_max_s: Positive = 10.0
    """The longest the settle on arrival waits for ``fine_settle_sd_m``."""
    creep_speed: Positive = 0.03
    """The slowest creep along the leg (m/s): each creep ends at it."""
    creep_max_speed: Positive = 0.1
    """The fastest creep (m/s). A creep goes at its remaining distance per second,
    between ``creep_speed`` and this: a long one (the estimate moved while the robot
    came in) takes seconds, not tens of them, and each still ends as slowly, so it
    overshoots no more."""
    creep_turn_rate: Positive = 0.02
    """The turn rate of a heading trim (rad/s)."""
    creep_latency_s: Positive = 0.2
    """How long a creep command takes to show in the pose (drivetrain lag plus the
    estimate's): the creep stops this much early so it does not overshoot."""
    fine_moves: Annotated[int, msgspec.Meta(ge=0)] = 6
    """At most this many creeps (re-approaches included) and as many heading trims."""
    reapproach_m: Positive = 0.8
    """A sideways offset cannot be crept away by a skid-steer robot: it backs up this far
    along the leg (at most the leg's length) and comes in again slowly, so that its pose
    estimate, settled while standing, is carried by odometry rather than pulled by each
    moving fix."""
    reapproach_speed: Positive = 0.1
    """The speed of a re-approach (m/s)."""
    reapproaches: Annotated[int, msgspec.Meta(ge=0)] = 2
    """At most this many re-approaches."""
    reapproach_tolerance_m: Positive = 0.04
    """At the route's end, a sideways offset from the leg beyond this is re-approached
    (m). With ``fine_tolerance_m`` along the leg it keeps the stop inside the mission's
    5 cm arrival check (2 and 4 cm make 4.5 cm); a re-approach costs about 20 s, and
    visibility tolerates stops far further off (``phenorover.eval.tolerance``)."""
    arrival_heading_tolerance_deg: Annotated[float, msgspec.Meta(gt=0, le=180)] = 2.0
    """Arrival is declared only within this angle of the route's planned heading (and
    within the route's own distance, ``FollowRoute.arrival_tolerance_m``, the mission's
    ``arrival_tolerance_m``); else the route fails: a scan must never be taken where the
    robot merely stopped. It is its own setting, not the in-place turn's
    ``heading_tolerance_deg``: a last leg without a final turn ends at the angle pure
    pursuit steered to close a sideways offset."""
    join_distance_m: Positive = 0.5
    """A route sent with ``join`` starts on the first leg passing this close to the robot
    (lanes are 1.8 m apart or more, so a neighbouring lane never qualifies)."""
