"""Reading the simulator's truth of a scan, ``<scan>.truth.json`` beside its E57.

The simulator writes it (:mod:`services.sim.truth_file`, which owns the schema); only
the evaluation reads it. A real scan has none.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import msgspec
import numpy as np

from common.poses import F64, PoseError, check_pose
from services.sim.truth_file import ScanTruth, truth_path


class TruthError(ValueError):
    """A truth file that is there but unusable; the message names it."""


def read_truth(scan: str | Path) -> ScanTruth | None:
    """The truth of the scan file ``scan``, None when there is none (a real scan);
    raises TruthError naming the file when it is malformed."""
    path = truth_path(scan)
    if not path.exists():
        return None
    try:
        return msgspec.json.decode(path.read_bytes(), type=ScanTruth)
    except (OSError, msgspec.DecodeError) as exc:
        raise TruthError(f"{path}: {exc}") from None


def find_truth(scan: str | Path, dirs: Sequence[Path] = ()) -> ScanTruth | None:
    """The truth of ``scan``: beside it, else beside a file of the same name in one of
    ``dirs`` (a card copied elsewhere); None when there is none. Raises TruthError."""
    p = Path(scan)
    for candidate in [p, *(d / p.name for d in dirs)]:
        truth = read_truth(candidate)
        if truth is not None:
            return truth
    return None


def true_pose(truth: ScanTruth, what: str) -> F64:
    """The true 4x4 ``field <- scanner`` pose; raises TruthError naming ``what``."""
    try:
        return check_pose(np.asarray(truth.scanner_pose, dtype=np.float64), what)
    except (PoseError, ValueError) as exc:
        raise TruthError(str(exc)) from None
