"""The pose graph of a registration: every scan held to its navigation pose by a
prior of what that pose is worth, each kept pair of scans pulling the two towards
the relative pose their clouds gave, and each registration sphere seen by two or
more scans pulling its fitted centres onto one position (see
:mod:`services.register.refine`). Poses are 4x4 ``field <- scanner``."""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from common.poses import F64, apply, inv
from services.register.poses import perturb

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True, eq=False)
class PairResult:
    """GICP of scan ``j`` (source) onto scan ``i`` (target): ``t_ij`` maps j's scanner
    frame into i's; ``info`` (6x6, rotation first, i's frame) its information;
    ``overlap`` the share of j's points with a correspondence; ``kept`` whether
    the pose graph uses it and ``reason`` why not."""

    i: int
    j: int
    t_ij: F64
    info: F64
    overlap: float
    rmse: float
    kept: bool
    reason: str = ""


@dataclasses.dataclass(frozen=True)
class TargetObservation:
    """Sphere ``target`` (a label from :func:`.targets.match_targets`) seen by scan
    ``scan`` at ``centre`` (3,) in its scanner frame."""

    scan: int
    target: int
    centre: F64


def optimise_graph(
    nav: list[F64],
    pairs: list[PairResult],
    sigmas: F64,
    targets: list[TargetObservation] | None = None,
    target_sigma: float = 0.003,
) -> list[F64]:
    """Poses minimising the whitened pair residuals plus navigation priors with 1-sigma
    ``sigmas`` (see :func:`prior_sigmas`). Pair residual: the rotation vector and
    translation of ``inv(T_i) T_j inv(t_ij)``, whitened by ``info``'s Cholesky
    factor. Each target observation pulls its centre placed by the scan's pose onto
    the target's position (unknown, solved with the poses) with ``target_sigma``."""
    edges = []
    for p in pairs:
        if not p.kept:
            continue
        w, v = np.linalg.eigh(p.info)
        # a pair blind in some direction (a flat ground patch) adds nothing there
        sqrt_info = (v * np.sqrt(np.maximum(w, 0.0))).T
        edges.append((p.i, p.j, inv(p.t_ij), sqrt_info))
    n = len(nav)
    obs = targets or []
    n_t = 1 + max((o.target for o in obs), default=-1)
    # targets start where the navigation places them (mean of their observations)
    x0_t = np.zeros((n_t, 3))
    for k in range(n_t):
        x0_t[k] = np.mean([apply(nav[o.scan], o.centre[None])[0] for o in obs if o.target == k], 0)

    def poses(x: F64) -> list[F64]:
        return [perturb(nav[k], x[6 * k : 6 * k + 3], x[6 * k + 3 : 6 * k + 6]) for k in range(n)]

    def residuals(x: F64) -> F64:
        ps = poses(x)
        out = [x[: 6 * n] / np.tile(sigmas, n)]
        for i, j, z_inv, sq in edges:
            e = inv(ps[i]) @ ps[j] @ z_inv
            delta = np.concatenate([Rotation.from_matrix(e[:3, :3]).as_rotvec(), e[:3, 3]])
            out.append(sq @ delta)
        tgt = x[6 * n :].reshape(-1, 3)
        for o in obs:
            out.append((apply(ps[o.scan], o.centre[None])[0] - tgt[o.target]) / target_sigma)
        return np.concatenate(out)

    x0 = np.concatenate([np.zeros(6 * n), x0_t.ravel()])
    scale = np.concatenate([np.tile(sigmas, n), np.full(3 * n_t, sigmas[0])])
    sol = least_squares(residuals, x0, method="trf", x_scale=scale)
    log.info(
        "pose graph: %d scans, %d pairs, %d target observations, cost %.3g",
        n,
        len(edges),
        len(obs),
        sol.cost,
    )
    return poses(sol.x)
