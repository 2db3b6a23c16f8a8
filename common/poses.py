"""Poses of scans: the navigation pose of a scan (paper eq. 1) and small SE(3) helpers,
shared by registration (which places and refines scans) and the dashboard (which
shows a finished scan where navigation put it).

The scanner pose is ``field <- scanner`` = ``[R | t]`` with

    R = Rz(yaw_base + mount_yaw) Ry(pitch) Rx(roll)
    t = p_base + R Rz(-mount_yaw) lever

- ``p_base``, ``yaw_base``: the base_link position and heading in the ``field`` frame
  from the EKF (RTK-GNSS + dual-antenna compass + odometry), averaged over the scan.
- ``pitch``, ``roll``: the scanner's dual-axis compensator. It measures the tilt of
  the scanner relative to gravity, which is exactly the pitch and roll of the ZYX
  (yaw-pitch-roll, REP-103) Euler decomposition: gravity in the scanner frame is
  ``R^T (0, 0, -1) = -(-sin p, cos p sin r, cos p cos r)``, independent of yaw. So the
  compensator's angles go straight into Ry and Rx, *inside* the yaw rotation, and the
  heading from the compass supplies only Rz. A compensator that reports the
  inclinations of its x and y axes to the horizontal instead is converted with
  :func:`tilt_from_axis_inclinations` (they differ at second order, ~0.001 deg at 2
  deg of tilt).
- ``lever``: the optical centre in base_link (m). The scanner sits rigidly on the
  base, so the base tilts with it and the lever arm turns with the full ``R``
  (a 1 m lever moves the centre ~1.7 cm per degree of tilt).
- ``mount_yaw``: a yaw offset of the scanner's zero azimuth from base_link x.

Angles in radians, distances in metres; poses are 4x4 float64 arrays.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from common.arrays import F64
from common.geo import rot_zyx


class PoseError(ValueError):
    """A pose or pose input that is not usable (wrong shape, not finite)."""


def check_pose(m: npt.ArrayLike, what: str = "pose") -> F64:
    """``m`` as a float64 4x4 rigid transform; raises PoseError naming ``what``."""
    a = np.asarray(m, dtype=np.float64)
    if a.shape != (4, 4) or not np.all(np.isfinite(a)):
        raise PoseError(f"{what}: expected a finite 4x4 transform, got shape {a.shape}")
    r = a[:3, :3]
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
        raise PoseError(f"{what}: rotation part is not a proper rotation")
    return a


def scanner_pose(
    x: float,
    y: float,
    z: float,
    yaw: float,
    pitch: float,
    roll: float,
    lever: tuple[float, float, float] = (0.0, 0.0, 1.0),
    mount_yaw: float = 0.0,
) -> F64:
    """4x4 ``field <- scanner`` from the base_link pose (x, y, z, yaw; field frame) and
    the compensator's pitch and roll; see the module docstring. Raises PoseError on
    non-finite input."""
    vals = (x, y, z, yaw, pitch, roll, *lever, mount_yaw)
    if not all(math.isfinite(v) for v in vals):
        raise PoseError(f"navigation pose has a non-finite value: {vals}")
    r = rot_zyx(roll, pitch, yaw + mount_yaw)
    m = np.eye(4)
    m[:3, :3] = r
    m[:3, 3] = np.array([x, y, z]) + r @ rot_zyx(0.0, 0.0, -mount_yaw) @ np.asarray(lever)
    return m


def tilt_from_axis_inclinations(incl_x: float, incl_y: float) -> tuple[float, float]:
    """(pitch, roll) from the inclinations of the scanner's x and y axes above the
    horizontal (nose up and left side up positive, radians). REP-103 pitch is nose
    *down* positive: ``sin(incl_x) = -sin(pitch)``, ``sin(incl_y) = cos(pitch) sin(roll)``.
    """
    pitch = -incl_x
    s = math.sin(incl_y) / max(math.cos(pitch), 1e-12)
    return pitch, math.asin(min(max(s, -1.0), 1.0))


def inv(m: F64) -> F64:
    """Inverse of a rigid 4x4 transform."""
    out = np.eye(4)
    out[:3, :3] = m[:3, :3].T
    out[:3, 3] = -m[:3, :3].T @ m[:3, 3]
    return out


def apply(m: F64, pts: F64) -> F64:
    """Points (N, 3) mapped through the 4x4 transform ``m``."""
    out: F64 = pts @ m[:3, :3].T + m[:3, 3]
    return out
