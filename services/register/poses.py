"""The pose graph's parametrisation of a pose change: a rotation vector and a
translation, both in the ``field`` frame (tilt about field x/y, heading about z).
The navigation pose itself (paper eq. 1) and the other SE(3) helpers are in
:mod:`common.poses`, shared with the dashboard.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from common.poses import F64


def perturb(m: F64, dxyz: npt.ArrayLike, drot: npt.ArrayLike) -> F64:
    """``m`` with its rotation turned by the rotation vector ``drot`` (field frame,
    rad) and its origin moved by ``dxyz`` (m): the parametrisation the pose graph
    and the navigation priors use (tilt about field x/y, heading about z)."""
    out = m.copy()
    out[:3, :3] = Rotation.from_rotvec(np.asarray(drot, dtype=float)).as_matrix() @ m[:3, :3]
    out[:3, 3] = m[:3, 3] + np.asarray(dxyz, dtype=float)
    return out


def difference(a: F64, b: F64) -> tuple[F64, F64]:
    """(dxyz, drot) with ``a == perturb(b, dxyz, drot)``."""
    drot: F64 = Rotation.from_matrix(a[:3, :3] @ b[:3, :3].T).as_rotvec()
    return a[:3, 3] - b[:3, 3], drot
