"""Ground truth the simulator writes for the evaluation only: of every scan, and of
the plants.

The simulator knows where the scanner really stood; a real scanner does not, so this
file exists only in simulation. The simulator writes it (this module: its schema and
writer); only the evaluation reads it (``phenorover/eval/register/truth.py``, behind
``phenorover eval register``). Nothing that places or registers scans may use it.
``<scan>.e57`` gets ``<scan>.truth.json``.

The plants' truth (:class:`PlantTruth`: every plot's true canopy traits, computed from
the simulated plants by :mod:`services.sim.plant_truth`, and what its plants were
grown from) is written once when the simulator starts, as
``<run_dir>/sim/plants.truth.json`` beside the world snapshot. Only the evaluation
reads it (to score measured traits and plans made from a survey); no product service
(traits, planner, mission) may open it.
"""

from __future__ import annotations

import datetime
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import numpy.typing as npt

from common.canopy import CanopyDefinition
from common.files import write_atomic
from services.sim.plant_config import TrialConfig
from services.sim.robot import RobotState

PLANTS_TRUTH = "plants.truth.json"


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
    write_atomic(truth_path(scan), msgspec.json.encode(truth), durable=True)


def scan_truth(stamp_ns: int, pose: npt.NDArray[np.float64], st: RobotState) -> ScanTruth:
    """The truth of a scan measured at ``stamp_ns`` from ``pose`` (4x4) with the robot
    at ``st``."""
    return ScanTruth(
        stamp_ns=stamp_ns,
        scanner_pose=pose.tolist(),
        x=st.x,
        y=st.y,
        z=st.z,
        roll=st.roll,
        pitch=st.pitch,
        yaw=st.yaw,
    )


class PlantTruth(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The true plants of a simulated field (evaluation only). ``date``: the survey
    date (None: mature plants); ``days_after_planting`` from the field's
    ``planting_date``; ``trial``: the world's trial config; ``definition``: the canopy
    definition the traits follow; ``plots``: one row per plot in plot order (see
    :mod:`services.sim.plant_truth`; metres, m2, m3, field frame)."""

    evaluation_only: bool = True
    field: str
    seed: int
    date: datetime.date | None
    planting_date: datetime.date | None
    days_after_planting: int | None
    trial: TrialConfig
    definition: CanopyDefinition
    plots: list[dict[str, Any]]
