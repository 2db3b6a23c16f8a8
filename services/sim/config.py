from typing import Annotated

import msgspec

from services.sim.render import ScanSettings
from services.sim.world import WorldConfig

Hz = Annotated[float, msgspec.Meta(gt=0, le=1000)]


class SimConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The simulated world (the field is the deployment's ``field``).

    ``real_time_factor``: sim seconds per wall second. ``clock_hz``: the physics step
    and sim-clock rate (sim time); every sim-clock service advances in these steps.
    ``start``: the robot's start pose (x, y in m, yaw in deg) in the field frame;
    empty = the field's origin corner facing along +x.
    ``inclinometer_sd_deg``: the scanner's dual-axis compensator, 0.015 deg (FARO Focus
    S spec: compensator accuracy 0.015 deg).
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
    motor_timeout_s: Annotated[float, msgspec.Meta(gt=0)] = 0.25
