"""What a survey reads from the bus, and how it is told to stop waiting."""

from __future__ import annotations

from collections.abc import Callable

from common import keys
from common.messages.base import BatteryState
from common.messages.nav import NavProgress, PoseEstimate
from common.messages.scan import ScannerStatus
from common.transport import Bus, Latest


class Aborted(Exception):
    """The operator aborted, or the service is stopping."""


class Feeds:
    """What a survey reads from the bus, subscribed once per service (a subscriber per
    survey would add four threads for every mission the service ever runs): the newest
    pose, route progress, scanner status and battery state, and each pose handed to
    ``on_pose``."""

    def __init__(self, bus: Bus) -> None:
        self.pose: Latest[PoseEstimate] = bus.latest(keys.NAV_POSE)
        self.progress: Latest[NavProgress] = bus.latest(keys.NAV_PROGRESS)
        self.scanner: Latest[ScannerStatus] = bus.latest(keys.SCANNER_STATUS)
        self.battery: Latest[BatteryState] = bus.latest(keys.BASE_BATTERY)
        self.on_pose: Callable[[PoseEstimate], None] = lambda _p: None
        bus.subscribe(keys.NAV_POSE, lambda p: self.on_pose(p))
