"""Dual-antenna GNSS compass (paper eq. 2), pure.

Antenna 1 is the rear one and antenna 2 the front one, both on the robot's +x axis
(``base_link``), 0.95 m apart in the paper's build; their mounting comes from the robot
description (:mod:`common.robot`) through :meth:`Compass.of`. Their positions come in a local
ENU-aligned frame (``map`` or ``field``; metres), and the heading is the yaw of
``base_link`` in that same frame (REP-103: 0 along +x, counter-clockwise positive,
wrapped to [-pi, pi)). In ``map`` (ENU) yaw 0 points east, not north.

A wrong measured baseline length is how a float fix, multipath or a wrong antenna
assignment shows itself, so headings whose baseline disagrees with the mounting by
more than ``baseline_tolerance_m`` are rejected with :class:`BaselineMismatch`.
"""

from __future__ import annotations

import math

import msgspec
import numpy as np
import numpy.typing as npt

from common.geo import wrap_angle
from common.messages.core import Positive
from common.robot import Robot, default_robot


class CompassError(ValueError):
    """The two fixes do not give a trustworthy heading."""


class BaselineMismatch(CompassError):
    """The measured antenna separation disagrees with the configured mounting."""


class CompassConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """``[services.gnss.compass]``."""

    baseline_tolerance_m: Positive = 0.05
    """A heading whose measured antenna separation differs from the mounted one by more
    is rejected. 5 cm is about 5 sigma of the along-baseline error of two independent
    7 mm RTK fixes (sqrt(2) * 7 mm ~ 1 cm), and below what a float fix (decimetres)
    usually gives."""


class Compass(msgspec.Struct, frozen=True, kw_only=True):
    """The compass as mounted: both antennas' phase centres in ``base_link`` (x
    forward, y left, z up; metres) and the baseline tolerance (m)."""

    antenna1_xyz_m: tuple[float, float, float]
    antenna2_xyz_m: tuple[float, float, float]
    baseline_tolerance_m: float = 0.05

    @classmethod
    def of(cls, robot: Robot, cfg: CompassConfig | None = None) -> Compass:
        """The compass on ``robot`` (its antennas 1 and 2), tolerance from ``cfg``."""
        cfg = cfg or CompassConfig()
        a1, a2 = robot.antennas
        return cls(
            antenna1_xyz_m=a1.xyz,
            antenna2_xyz_m=a2.xyz,
            baseline_tolerance_m=cfg.baseline_tolerance_m,
        )

    def __post_init__(self) -> None:
        if self.baseline_m < 0.1:
            raise ValueError(f"antennas {self.baseline_m:.3f} m apart: too close for a compass")

    @property
    def baseline_m(self) -> float:
        """Configured 3D antenna separation (metres)."""
        return math.dist(self.antenna1_xyz_m, self.antenna2_xyz_m)

    @property
    def mount_yaw_rad(self) -> float:
        """Yaw of the antenna1 -> antenna2 vector in ``base_link`` (0 when along +x)."""
        (x1, y1, _), (x2, y2, _) = self.antenna1_xyz_m, self.antenna2_xyz_m
        return math.atan2(y2 - y1, x2 - x1)

    @property
    def mount_pitch_rad(self) -> float:
        """Pitch of the antenna1 -> antenna2 vector in ``base_link`` (REP-103 sign)."""
        (x1, y1, z1), (x2, y2, z2) = self.antenna1_xyz_m, self.antenna2_xyz_m
        return math.atan2(-(z2 - z1), math.hypot(x2 - x1, y2 - y1))


class CompassHeading(msgspec.Struct, frozen=True, kw_only=True):
    """Heading of ``base_link`` (radians) with its 1-sigma, the measured 3D baseline
    (metres) and the pitch along the baseline (REP-103: positive is nose down)."""

    yaw_rad: float
    yaw_std_rad: float
    baseline_m: float
    pitch_rad: float


def _cov_xy(cov: npt.ArrayLike, which: str) -> npt.NDArray[np.float64]:
    c = np.asarray(cov, dtype=float)
    if c.shape not in ((2, 2), (3, 3)) or not np.all(np.isfinite(c)):
        raise CompassError(f"{which} covariance must be a finite 2x2 or 3x3 matrix, got {c!r}")
    return c[:2, :2]


def compass_heading(
    p1: npt.ArrayLike,
    p2: npt.ArrayLike,
    cov1: npt.ArrayLike,
    cov2: npt.ArrayLike,
    cfg: Compass | None = None,
) -> CompassHeading:
    """Heading from antenna 1 (rear) at ``p1`` and antenna 2 (front) at ``p2``.

    ``p1``, ``p2``: (x, y, z) in an ENU-aligned frame, metres (x, y suffices when the
    heights are unknown; pitch is then 0 and the baseline check is horizontal).
    ``cov1``, ``cov2``: their position covariances (2x2 or 3x3, m^2). The yaw sigma is
    the first-order propagation of the errors perpendicular to the baseline:
    ``sqrt(var_perp1 + var_perp2) / horizontal_baseline``.

    Raises :class:`BaselineMismatch` when the measured baseline is off by more than
    the tolerance, :class:`CompassError` on malformed input.
    """
    cfg = cfg or Compass.of(default_robot())
    a, b = np.asarray(p1, dtype=float), np.asarray(p2, dtype=float)
    if a.shape != b.shape or a.shape not in ((2,), (3,)) or not np.all(np.isfinite(a - b)):
        raise CompassError(f"antenna positions must be finite 2- or 3-vectors: {a!r}, {b!r}")
    c1, c2 = _cov_xy(cov1, "antenna 1"), _cov_xy(cov2, "antenna 2")
    d = b - a
    horiz = math.hypot(d[0], d[1])
    dz = float(d[2]) if d.shape == (3,) else 0.0
    measured = math.hypot(horiz, dz)
    expected = (
        cfg.baseline_m
        if d.shape == (3,)
        else math.hypot(
            cfg.antenna2_xyz_m[0] - cfg.antenna1_xyz_m[0],
            cfg.antenna2_xyz_m[1] - cfg.antenna1_xyz_m[1],
        )
    )
    if abs(measured - expected) > cfg.baseline_tolerance_m:
        raise BaselineMismatch(
            f"GNSS compass baseline {measured:.3f} m, expected {expected:.3f} m "
            f"+/- {cfg.baseline_tolerance_m:.3f} m"
        )
    if horiz < 0.5 * measured:
        raise CompassError(
            f"GNSS compass baseline is {math.degrees(math.atan2(abs(dz), horiz)):.0f}"
            " deg from horizontal: no usable heading"
        )
    # Paper eq. 2, with atan2 placing the angle in the right quadrant.
    psi = math.atan2(float(d[1]), float(d[0]))
    perp = np.array([-math.sin(psi), math.cos(psi)])
    var = float(perp @ c1 @ perp + perp @ c2 @ perp)
    return CompassHeading(
        yaw_rad=wrap_angle(psi - cfg.mount_yaw_rad),
        yaw_std_rad=math.sqrt(max(var, 0.0)) / horiz,
        baseline_m=measured,
        pitch_rad=math.atan2(-dz, horiz) - cfg.mount_pitch_rad,
    )
