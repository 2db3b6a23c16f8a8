from __future__ import annotations

import argparse
import json
from typing import Annotated

import msgspec

from common.config import ConfigError, load_manifest
from common.messages.core import RobotName
from services.sim.faults import Fault
from services.sim.imu import ImuConfig
from services.sim.render import ScanSettings
from services.sim.world import WorldConfig

Hz = Annotated[float, msgspec.Meta(gt=0, le=1000)]


class SimRobotConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """One robot of a shared world (:mod:`services.sim.robots`): its ``namespace``
    (its manifest's) and its ``start`` pose (x, y in m, yaw in deg; empty: its home
    beside the field, facing the field)."""

    namespace: RobotName
    start: tuple[float, float, float] | None = None


class SimConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The simulated world (the field is the deployment's ``field``).

    ``real_time_factor``: sim seconds per wall second. ``clock_hz``: the physics step
    and sim-clock rate (sim time); every sim-clock service advances in these steps.
    ``start``: the robot's start pose (x, y in m, yaw in deg) in the field frame;
    empty = the field's origin corner facing along +x. ``robots``: several robots
    sharing the world, each in its namespace (:mod:`services.sim.robots`); empty:
    one, with the plain keys.
    ``inclinometer_sd_deg``: the scanner's dual-axis compensator, 0.015 deg (FARO Focus
    S spec: compensator accuracy 0.015 deg).
    ``resume``: a simulator that died and is restarted within its deployment (same
    parent process: the launcher) continues the world (sim time, robot, noise) saved
    in ``<run_dir>/sim/world.json`` for the same field and world config, so the sim
    clocks of the other services do not stall at the time they had (see
    :mod:`services.sim.snapshot`); false: always start afresh at 0. ``snapshot_s``:
    wall seconds between saves (0: never save).
    ``scan_dir``: the only folder rendered scans may be written under (the scanner's
    card); empty: the manifest's ``[services.scanner] storage_dir`` when the manifest
    has one, else the run folder.
    ``imu``: the Husky's UM7-class IMU (:mod:`services.sim.imu`).
    ``faults``: device faults scheduled in sim time, ``[[services.sim.faults]]`` entries
    (see :mod:`services.sim.faults` and docs/faults.md); simulation only, the truth
    is never touched.
    ``start_held``: in lockstep (the manifest's ``lockstep``), the world stands at its
    start until asked to run (``rpc/sim/run``): whoever starts a survey or an
    experiment does so first, so the same seed gives the same run.
    ``nice``: how far the simulator yields the CPU to the services it feeds (a Unix
    nice increment, 0: not at all). On a machine too busy for ``real_time_factor``
    the world then slows down, as the services are not able to in the field: at the
    same priority it kept its pace and the services fell seconds of sim time behind
    their own sensors, for good (a backlog a saturated machine never drains).
    """

    real_time_factor: Annotated[float, msgspec.Meta(gt=0, le=1000)] = 1.0
    clock_hz: Hz = 50.0
    truth_hz: Hz = 10.0
    gnss_hz: Hz = 10.0
    lidar_hz: Hz = 10.0
    seed: int = 0
    start: tuple[float, float, float] | None = None
    world: WorldConfig = msgspec.field(default_factory=WorldConfig)
    scan: ScanSettings = msgspec.field(default_factory=ScanSettings)
    inclinometer_sd_deg: Annotated[float, msgspec.Meta(ge=0)] = 0.015
    imu: ImuConfig = msgspec.field(default_factory=ImuConfig)
    motor_timeout_s: Annotated[float, msgspec.Meta(gt=0)] = 0.25
    resume: bool = True
    snapshot_s: Annotated[float, msgspec.Meta(ge=0, le=3600)] = 0.5
    scan_dir: str = ""
    faults: list[Fault] = msgspec.field(default_factory=list)
    nice: Annotated[int, msgspec.Meta(ge=0, le=19)] = 10
    start_held: bool = False
    robots: list[SimRobotConfig] = msgspec.field(default_factory=list)


class SimCli:
    """No flags of its own: fills an unset ``scan_dir`` from the manifest's scanner
    section, so the simulator writes scans exactly where that scanner reads them."""

    def add(self, parser: argparse.ArgumentParser) -> None:
        pass

    def overrides(self, args: argparse.Namespace) -> list[str]:
        if args.manifest is None or any(s.startswith("scan_dir=") for s in args.set):
            return []
        try:
            m = load_manifest(args.manifest)
        except ConfigError:
            return []  # reported by the runner, which reads it next
        if "scan_dir" in m.services.get("sim", {}):
            return []
        card = m.services.get("scanner", {}).get("storage_dir")
        return [f"scan_dir={json.dumps(card)}"] if isinstance(card, str) else []
