"""Registration errors against the simulator's truth (metres, ``field`` frame).

For every method (navigation only, navigation + C2C, C2C without the spheres when the
registration has it, target-based):

- target errors: every sphere centre a scan observed, placed by the method's pose,
  against the target's true position (the mean of its observations placed by the
  true poses): mean 3D, mean horizontal, mean absolute vertical and max;
- scan point errors: each scan's points (a uniform subsample) placed by the method's
  pose against the same points placed by the true pose: max, mean, mean per scan.

The statistics are the registration's own (:mod:`services.register.metrics`), so a
figure against the truth and one against the target-based reference mean the same.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import msgspec
import numpy as np

from common.arrays import I64
from common.poses import F64, apply
from services.register.metrics import PointStats, TargetStats, point_stats, subsample, target_stats
from services.register.outcome import Registration

# (key in report.json, label)
METHODS = (
    ("navigation", "Nav. sensors only"),
    ("c2c", "Nav. sensors + C2C"),
    ("c2c_without_targets", "Nav. sensors + C2C, spheres left out"),
    ("target_based", "Target-based"),
)


class MethodTruth(msgspec.Struct, frozen=True, kw_only=True):
    """One method against the truth (m; see the module docstring)."""

    targets: TargetStats
    points: PointStats


class TruthScore(msgspec.Struct, frozen=True, kw_only=True):
    """Every method against the truth: ``scans`` scored, ``targets`` with a true
    position, ``methods`` by the keys of :data:`METHODS` present."""

    scans: int
    targets: int
    methods: dict[str, MethodTruth]


@dataclasses.dataclass(frozen=True, eq=False)
class ScanEvidence:
    """What scoring needs of one scan: its points (N, 3) and the sphere centres it
    found (M, 3), both in its scanner frame, and each centre's target (M,; -1: none)."""

    points: F64
    centres: F64
    labels: I64


def true_targets(scans: Sequence[ScanEvidence], true_poses: Sequence[F64]) -> F64:
    """(K, 3) true target positions: per label, the mean of its observations placed by
    the true poses (NaN for a label nobody observed)."""
    k = max((int(s.labels.max()) + 1 for s in scans if len(s.labels)), default=0)
    out = np.full((k, 3), np.nan)
    for t in range(k):
        obs = [apply(p, s.centres[s.labels == t]) for s, p in zip(scans, true_poses, strict=True)]
        found = [o for o in obs if len(o)]
        if found:
            out[t] = np.vstack(found).mean(axis=0)
    return out


def score(
    scans: Sequence[ScanEvidence],
    poses: Mapping[str, Sequence[F64]],
    true_poses: Sequence[F64],
    sample_points: int = 5000,
    seed: int = 0,
) -> TruthScore:
    """Every method's ``poses`` (per scan, 4x4 ``field <- scanner``) against
    ``true_poses``. Raises ValueError when the counts of scans and poses differ."""
    n = len(scans)
    for name, ps in [("true", true_poses), *poses.items()]:
        if len(ps) != n:
            raise ValueError(f"{name} poses: {len(ps)} for {n} scans")
    rng = np.random.default_rng(seed)
    samples = [subsample(s.points, sample_points, rng) for s in scans]
    centres = [s.centres for s in scans]
    labels = [s.labels for s in scans]
    truth = true_targets(scans, true_poses)
    methods = {
        name: MethodTruth(
            targets=target_stats(centres, labels, list(poses[name]), truth),
            points=point_stats(samples, list(poses[name]), list(true_poses)),
        )
        for name, _ in METHODS
        if name in poses
    }
    known = int(np.all(np.isfinite(truth), axis=1).sum())
    return TruthScore(scans=n, targets=known, methods=methods)


def score_registration(
    reg: Registration, true_poses: Sequence[F64], sample_points: int = 5000, seed: int = 0
) -> TruthScore:
    """An in-memory registration (:func:`services.register.pipeline.register`) against
    the true poses of its scans, in order."""
    scans = [
        ScanEvidence(s.points, np.asarray(c, dtype=np.float64).reshape(-1, 3), lab)
        for s, c, lab in zip(reg.scans, reg.centres, reg.labels, strict=True)
    ]
    poses: dict[str, Sequence[F64]] = {
        "navigation": reg.nav_poses,
        "c2c": reg.c2c_poses,
        "target_based": reg.target_poses,
    }
    if reg.plain_poses is not None:
        poses["c2c_without_targets"] = reg.plain_poses
    return score(scans, poses, true_poses, sample_points, seed)
