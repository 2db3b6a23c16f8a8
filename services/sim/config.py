from __future__ import annotations

import argparse
import json
from typing import Annotated

import msgspec

from common.config import ConfigError, load_manifest
from common.messages.core import Coordinate, NonNegative, Positive, RobotName, Seed
from services.sim.faults import Fault
from services.sim.imu import ImuConfig
from services.sim.render import ScanSettings
from services.sim.world_config import WorldConfig

Hz = Annotated[float, msgspec.Meta(gt=0, le=1000)]

# a start pose's yaw (deg): two turns either way, as a hand-written start might give
YawDeg = Annotated[float, msgspec.Meta(ge=-720.0, le=720.0)]


class SimRobotConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """One robot of a shared world (:mod:`services.sim.robots`, docs/fleet.md)."""

    namespace: RobotName
    """Its manifest's namespace: its devices are on that namespace's keys."""
    start: tuple[Coordinate, Coordinate, YawDeg] | None = None
    """Its start pose ``[x, y, yaw_deg]`` (m, deg); none: its home from
    :func:`common.lanes.homes` (edge lanes in turn from the Origin's cross lane), facing
    the field, where a plan with ``home = "origin"`` parks it."""


class SimConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The simulated world (the field is the deployment's ``field``)."""

    real_time_factor: Annotated[float, msgspec.Meta(gt=0, le=1000)] = 1.0
    """Sim seconds per wall second (in lockstep: at most; 1000 is as fast as the services
    go)."""
    clock_hz: Hz = 50.0
    """The physics step and sim-clock rate (sim time); every sim-clock service advances
    in these steps."""
    truth_hz: Hz = 10.0
    """The truth's output rate."""
    gnss_hz: Hz = 10.0
    """The antennas' output rate."""
    lidar_hz: Hz = 10.0
    """The lidar's output rate."""
    seed: Seed = 0
    """Noise seed (the world's shape has its own, ``world.seed``)."""
    start: tuple[Coordinate, Coordinate, YawDeg] | None = None
    """The robot's start pose ``[x, y, yaw_deg]`` in the field frame (m, deg); none: the
    field's origin corner, facing along +x."""
    world: WorldConfig = msgspec.field(default_factory=WorldConfig)
    """Terrain, foliage, targets, obstacles, soil, the robot's slip and encoder model,
    the FARO's noise, the lidar, the trial (docs/simulation.md)."""
    scan: ScanSettings = msgspec.field(default_factory=ScanSettings)
    """The rendered scan window and step (the paper's window)."""
    inclinometer_sd_deg: NonNegative = 0.015
    """The scanner's dual-axis compensator noise (FARO Focus S spec: compensator
    accuracy 0.015 deg)."""
    imu: ImuConfig = msgspec.field(default_factory=ImuConfig)
    """The Husky's UM7-class IMU (:mod:`services.sim.imu`, docs/simulation.md)."""
    motor_timeout_s: Positive = 0.25
    """The simulated base stops the wheels when no velocity command came for this long
    (sim time)."""
    resume: bool = True
    """A simulator that died and is restarted within its deployment (same parent
    process: the launcher) continues the world (sim time, robot, noise) saved in
    ``<run_dir>/sim/world.json`` for the same field and world config, so the sim clocks
    of the other services do not stall at the time they had
    (:mod:`services.sim.snapshot`); false: always start afresh at 0."""
    snapshot_s: Annotated[float, msgspec.Meta(ge=0, le=3600)] = 0.5
    """Wall seconds between saves of the world (0: never save)."""
    scan_dir: str = ""
    """The only folder rendered scans may be written under (the scanner's card); empty:
    the manifest's ``[services.scanner] storage_dir`` when the manifest has one, else
    the run folder."""
    faults: list[Fault] = msgspec.field(default_factory=list)
    """Device faults scheduled in sim time, ``[[services.sim.faults]]`` entries
    (:mod:`services.sim.faults`, docs/faults.md); simulation only, the truth is never
    touched."""
    nice: Annotated[int, msgspec.Meta(ge=0, le=19)] = 10
    """How far the simulator yields the CPU to the services it feeds (a Unix nice
    increment, 0: not at all), when it runs free. On a machine too busy for
    ``real_time_factor`` the world then slows down, as the services are not able to in
    the field: at the same priority it would keep its pace and the services fall
    seconds of sim time behind their own sensors, for good (a backlog a saturated
    machine never drains). In lockstep it is not lowered: each step waits for it."""
    start_held: bool = False
    """In lockstep (the manifest's ``lockstep``), the world stands at its start until
    asked to run (``rpc/sim/run``): whoever starts a survey or an experiment does so
    first, so the same seed gives the same run; ``phenorover sim`` sets it."""
    robots: list[SimRobotConfig] = msgspec.field(default_factory=list)
    """Several robots sharing the world, each in its namespace, its noise from ``seed``
    + 7919 k, its lidar seeing the others (:mod:`services.sim.robots`, docs/fleet.md);
    empty: one, with the plain keys."""


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
