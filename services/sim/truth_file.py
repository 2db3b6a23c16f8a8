"""Ground truth of a simulated scan, written next to its E57 for evaluation only.

The simulator knows where the scanner really stood; a real scanner does not, so this
file exists only in simulation. The simulator writes it (this module: its schema and
writer); only the evaluation reads it (``phenorover/eval/register/truth.py``, behind
``phenorover eval register``). Nothing that places or registers scans may use it.
``<scan>.e57`` gets ``<scan>.truth.json``.
"""

from __future__ import annotations

from pathlib import Path

import msgspec

from services.sim.storage import write_atomic


class ScanTruth(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The true scanner pose (4x4 ``field <- scanner``, row-major) and base_link pose
    (field frame; metres, radians) while the scan was measured. Evaluation only."""

    evaluation_only: bool = True
    stamp_ns: int
    scanner_pose: list[list[float]]
    x: float
    y: float
    z: float
    roll: float
    pitch: float
    yaw: float


def truth_path(scan: str | Path) -> Path:
    """Where the truth of the scan file ``scan`` is stored."""
    p = Path(scan)
    return p.with_name(p.stem + ".truth.json")


def write_truth(scan: str | Path, truth: ScanTruth) -> None:
    """Write the truth beside ``scan``, whole or not at all (temporary name, renamed)."""
    write_atomic(truth_path(scan), msgspec.json.encode(truth))
