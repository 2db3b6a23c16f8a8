"""Target-based registration: the paper's reference, from spheres seen in several scans.

1. Match: every sphere centre found in a scan is placed in the ``field`` frame with
   that scan's navigation pose; centres closer than ``match_radius`` are one target
   (the spheres stand metres apart, navigation errs by centimetres). A group holding
   two centres from the same scan is ambiguous and dropped.
2. Solve: all scan poses and target positions at once by least squares: each
   observation pulls ``T_i c_ik`` onto target ``X_k`` (``sigma_target``), the
   compensator holds each scan's tilt (``sigma_tilt_deg``, as FARO SCENE uses the
   inclinometer in target registration), and a weak navigation prior fixes only the
   global placement. With its tilt known a scan needs two targets (shared with other
   scans) to be fixed; scans with fewer keep their navigation pose and are reported
   unsolved.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Annotated

import msgspec
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from common.arrays import I64
from common.messages.core import Positive
from common.poses import F64, apply
from services.register.poses import perturb


class TargetConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Target matching and adjustment, the target-based reference (``[register.targets]``)."""

    match_radius: Positive = 0.5
    """Sphere centres placed by their scans' navigation poses and closer than this are
    one target (m)."""
    sigma_target: Positive = 0.002
    """1 sigma of a fitted sphere centre in the adjustment (m)."""
    sigma_tilt_deg: Positive = 0.02
    """1 sigma of the prior holding a scan's tilt to the compensator's (deg)."""
    sigma_nav_m: Positive = 0.5
    """1 sigma of the prior holding a scan's position to navigation's (m): gauge only,
    loose enough that the targets decide the relative placement."""
    sigma_nav_yaw_deg: Positive = 5.0
    """1 sigma of the prior holding a scan's heading to navigation's (deg), gauge only."""
    min_targets: Annotated[int, msgspec.Meta(ge=1)] = 2
    """A scan sharing fewer targets keeps its navigation pose and is reported unsolved."""


@dataclasses.dataclass(frozen=True, eq=False)
class TargetSolution:
    """Poses (4x4 field <- scanner) per scan, target positions (K, 3, field frame),
    per scan the number of matched targets and whether the targets fixed its pose,
    and the residual of every observation (m)."""

    poses: list[F64]
    centres: F64
    n_targets: list[int]
    solved: list[bool]
    residuals: F64


def match_targets(centres: list[F64], poses: list[F64], radius: float) -> list[I64]:
    """Target label of every centre (per scan an (n_i,) array; -1 = unmatched or
    ambiguous), grouping centres (scanner frame) placed by ``poses`` within
    ``radius``. Labels number groups seen by at least two scans from 0."""
    placed = [apply(p, np.asarray(c).reshape(-1, 3)) for c, p in zip(centres, poses, strict=True)]
    scan_of = np.concatenate([np.full(len(c), k) for k, c in enumerate(placed)]).astype(np.int64)
    allc = np.vstack(placed) if placed else np.zeros((0, 3))
    labels = np.full(len(allc), -1, dtype=np.int64)
    if len(allc):
        tree = cKDTree(allc)
        _, comp = connected_components(
            tree.sparse_distance_matrix(tree, radius, output_type="coo_matrix")
        )
        k = 0
        for g in np.unique(comp):
            members = np.flatnonzero(comp == g)
            scans = scan_of[members]
            if len(np.unique(scans)) == len(scans) >= 2:
                labels[members] = k
                k += 1
    bounds = np.cumsum([0] + [len(c) for c in placed])
    return [labels[bounds[i] : bounds[i + 1]] for i in range(len(placed))]


def solve_targets(
    centres: list[F64], nav: list[F64], cfg: TargetConfig | None = None
) -> TargetSolution:
    """Target-based registration of all scans (see the module docstring):
    ``centres[i]`` (n_i, 3) are sphere centres in scan i's frame, ``nav[i]`` its
    navigation pose."""
    cfg = cfg or TargetConfig()
    n = len(nav)
    labels = match_targets(centres, nav, cfg.match_radius)
    obs = [
        (i, int(lab), np.asarray(centres[i]).reshape(-1, 3)[m])
        for i in range(n)
        for m, lab in enumerate(labels[i])
        if lab >= 0
    ]
    n_t = 1 + max((o[1] for o in obs), default=-1)
    counts = [len({o[1] for o in obs if o[0] == i}) for i in range(n)]
    tilt, yaw = math.radians(cfg.sigma_tilt_deg), math.radians(cfg.sigma_nav_yaw_deg)
    sig = np.array([cfg.sigma_nav_m] * 3 + [tilt, tilt, yaw])
    # initial targets: the mean of their navigation placements
    x0_t = np.zeros((n_t, 3))
    for k in range(n_t):
        x0_t[k] = np.mean([apply(nav[i], c[None])[0] for i, kk, c in obs if kk == k], axis=0)

    def unpack(x: F64) -> tuple[list[F64], F64]:
        poses = [perturb(nav[i], x[6 * i : 6 * i + 3], x[6 * i + 3 : 6 * i + 6]) for i in range(n)]
        return poses, x[6 * n :].reshape(-1, 3)

    def residuals(x: F64) -> F64:
        poses, tgt = unpack(x)
        res = [(apply(poses[i], c[None])[0] - tgt[k]) / cfg.sigma_target for i, k, c in obs]
        return np.concatenate([*res, x[: 6 * n] / np.tile(sig, n)])

    x0 = np.concatenate([np.zeros(6 * n), x0_t.ravel()])
    scale = np.concatenate([np.tile(sig, n), np.full(3 * n_t, 0.05)])
    sol = least_squares(residuals, x0, method="trf", x_scale=scale)
    poses, tgt = unpack(sol.x)
    solved = [c >= cfg.min_targets for c in counts]
    # a scan the targets do not fix keeps its navigation pose
    poses = [p if ok else nav[i] for i, (p, ok) in enumerate(zip(poses, solved, strict=True))]
    res = np.array([np.linalg.norm(apply(poses[i], c[None])[0] - tgt[k]) for i, k, c in obs])
    return TargetSolution(poses, tgt, counts, solved, res)
