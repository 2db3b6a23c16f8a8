"""The localization filter's settings (``[services.nav.ekf]``)."""

from __future__ import annotations

from typing import Annotated

import msgspec

from common.messages.core import NonNegative, Positive


class EkfConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Process noise is a random walk on the velocities (accelerations, per s).
    Plausibility limits are what the filter refuses before it gates
    (:mod:`services.nav.ekf_guard`)."""

    accel_sd: Positive = 0.5
    """Process noise of the speed, m/s² (the Husky's commanded accelerations)."""
    yaw_accel_sd: Positive = 1.0
    """Process noise of the turn rate, rad/s²."""
    pos_process_sd: Positive = 0.005
    """Process noise of the position, m/sqrt(s): unmodelled slip and terrain."""
    yaw_process_sd: Positive = 0.005
    """Process noise of the heading, rad/sqrt(s)."""
    turn_slip_sd: NonNegative = 0.04
    """Process noise of the position per turn, m/sqrt(rad): a skid-steer turning in
    place also moves sideways, as uneven traction moves its rotation centre off the
    body centre (the paper's corner error: a few centimetres per quarter turn on
    tilled soil). Without it the filter holds the pose of the turn's start, refuses the
    fixes that show the shift, and the leg after the corner starts centimetres off the
    line it believes it is on. 0 leaves the turn to ``pos_process_sd`` alone."""
    gate: bool = True
    """Refuse a measurement whose innovation is outside the chi-square gate."""
    localized_sigma_m: Positive = 0.05
    """The largest 1-sigma position uncertainty at which the robot still counts as
    localized."""
    reset_after: Annotated[int, msgspec.Meta(ge=1)] = 10
    """After this many consecutive rejections of one measurement type that agree with
    each other (each innovation within the gate of the one before) the filter, not the
    sensor, is taken to be wrong: the states the measurement observes directly get their
    variance inflated and it is accepted (a heading that drifted during an unaided turn,
    or a position after a long outage, would otherwise lock every later measurement
    out). Rejections that disagree with each other (outliers, garbage) start the count
    again, so they never move the filter."""
    reset_after_still: Annotated[int, msgspec.Meta(ge=1)] = 100
    """``reset_after`` while standing still: after zero-velocity updates the filter is
    rarely wrong, while the GNSS error is correlated over seconds, so a 1 s run of
    rejections there is a multipath excursion to sit out, not a reason to jump to it."""
    gnss_correlation_s: Annotated[float, msgspec.Meta(ge=0, le=1e300)] = 2.0
    """GNSS errors are correlated over seconds (multipath): fixes taken while the robot
    stands or creeps repeat the same error, so there each one is fused with its variance
    scaled by 1 + 2 tau / interval, the variance of a mean of such samples (fading out
    toward full speed). Without it the covariance of a standing robot shrinks as if
    every fix were independent and claims millimetres it does not have, and a creep of a
    few millimetres lets the fixes of that moment pull the settled estimate. The
    compass's headings are scaled so at any speed: the heading's process noise is
    small (the gyro carries it), so the filter averages many of them while driving
    too, and taken as independent they steered the robot by their correlated error
    (a degree under the crop is 7 mm of cross-track at pure pursuit's 0.4 m
    look-ahead). 0 turns the correction off."""
    z_process_sd: Positive = 0.05
    """base_link's height: a random walk (m/sqrt(s), at full speed; the terrain's bumps
    and slope) observed by the antennas' RTK heights."""
    max_gap_s: Positive = 1.0
    """Predict at most this far in one step (s)."""
    dynamic_process_noise: bool = True
    """robot_localization's dynamic_process_noise_covariance: the position and heading
    process noise stand for slip, which needs motion, so it scales with the speed. A
    robot standing still then averages GNSS over the whole scan instead of following
    every fix's multipath wander."""
    full_noise_speed: Positive = 0.2
    """The speed (m/s or rad/s) at which the dynamic process noise is full."""
    still_speed: Positive = 0.01
    """Speeds below this (the encoders' noise; m/s and rad/s) count as standing."""
    still_noise_share: Annotated[float, msgspec.Meta(gt=0, le=1)] = 1e-5
    """The least share of the full process noise, standing."""
    zero_velocity_sd: Positive = 1e-4
    """Zero-velocity update: while the robot is known to stand (wheels commanded still
    and reading still), its velocities are measured as zero to this 1-sigma (m/s, rad/s)
    instead of integrating the encoders' noise into position and heading."""
    zero_velocity_updates: bool = True
    """Make the zero-velocity updates."""
    lag_compensation: bool = True
    """A GNSS measurement arrives ~0.1 s after its epoch: fuse it against the state of
    its epoch (the motion since taken back through the unicycle model), not as if it
    were new; false: as they arrive (robot_localization without smoothing)."""
    min_fix_sd_m: Positive = 0.001
    """Plausibility: a fix's position uncertainty is floored at this (m). No RTK receiver
    is better than a millimetre: a fix claiming 1e-30 m² would collapse the covariance
    to nothing and the gate would reject the truth ever after."""
    min_yaw_sd: Positive = 1e-4
    """Plausibility: a heading's uncertainty is floored at this (rad; no two-antenna
    compass is better than 0.006 deg)."""
    max_speed: Positive = 5.0
    """Plausibility: odometry faster than this (m/s) is refused (the velocity command's
    own bound, ``common.messages.base.Twist``)."""
    max_turn_rate: Positive = 10.0
    """Plausibility: odometry turning faster than this (rad/s) is refused."""
    max_stamp_skew_s: Positive = 5.0
    """Plausibility: a measurement stamped further than this from the filter's time (s)
    is refused. Services stamp on one clock (wall, or the sim's), so such a stamp is
    another clock or garbage; GNSS is ~0.1 s late and a restarted simulator resumes
    ~1 s behind."""
