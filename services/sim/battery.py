"""The simulated Husky's battery and the operator who swaps it.

The charge (the truth) falls by the robot description's discharge model
(:class:`common.battery.Battery`: standing and payload draw at all times, the drive's
while the wheels turn) and the battery management reports it exactly. With the charge
gone the wheels stop. The operator watches the mission's state, as a field technician
watches the dashboard: once the mission says it waits for a swap, a full battery is in
``swap_s`` of sim time later (the robot's computers stay up: the simulated swap is a
hot one; on the Husky it is a power cut, which the mission resumes from).
"""

from __future__ import annotations

import logging
import threading

from common.battery import Battery
from common.clock import NS
from common.messages.base import BatteryState
from common.messages.mission import MissionPhase, MissionState

# wheel speeds (m/s, rad/s) below which the drive draws nothing
STILL = 1e-3


class SimBattery:
    """``charge_wh``: where a restarted simulator's battery stood (None: full)."""

    def __init__(self, spec: Battery, log: logging.Logger, charge_wh: float | None = None) -> None:
        self.spec, self.log = spec, log
        self.charge_wh = spec.capacity_wh if charge_wh is None else charge_wh
        self.lowest_wh = self.charge_wh
        self.swaps = 0
        self.power_w = spec.power_w(False)
        self._lock = threading.Lock()
        self._waiting_since: int | None = None  # sim ns the mission began to wait
        self._below = False

    @property
    def empty(self) -> bool:
        return self.charge_wh <= 0.0

    @property
    def fraction(self) -> float:
        return max(0.0, self.charge_wh) / self.spec.capacity_wh

    def step(self, dt: float, v_wheel: float, w_wheel: float, now_ns: int) -> None:
        """Draw ``dt`` seconds' energy (the wheels turning at ``v_wheel``,
        ``w_wheel``), then let the operator swap if the swap is done by ``now_ns``."""
        moving = abs(v_wheel) > STILL or abs(w_wheel) > STILL
        with self._lock:
            was_empty = self.empty
            self.power_w = self.spec.power_w(moving)
            self.charge_wh = max(0.0, self.charge_wh - self.power_w * dt / 3600.0)
            self.lowest_wh = min(self.lowest_wh, self.charge_wh)
            if self.empty and not was_empty:
                self.log.error("battery (truth): empty, the wheels stop")
            below = self.charge_wh < self.spec.reserve_wh
            if below and not self._below:
                self.log.warning(
                    "battery (truth): %.1f %%, below the reserve of %g %%",
                    100 * self.fraction,
                    100 * self.spec.reserve,
                )
            self._below = below
            since = self._waiting_since
            if since is not None and now_ns - since >= self.spec.swap_s * NS:
                self._swap(now_ns)

    def _swap(self, now_ns: int) -> None:
        self.log.info(
            "battery (truth): swapped by the operator at sim time %.0f s (it was at %.1f %%)",
            now_ns / NS,
            100 * self.fraction,
        )
        self.charge_wh = self.spec.capacity_wh
        self.swaps += 1
        self._waiting_since = None
        self._below = False

    def on_mission(self, state: MissionState) -> None:
        """The operator sees the mission's state: a wait for a swap starts the clock."""
        with self._lock:
            if state.phase != MissionPhase.SWAPPING:
                self._waiting_since = None
            elif self._waiting_since is None:
                self._waiting_since = state.stamp_ns
                self.log.info("battery: the operator is on the way for a swap")

    def message(self, stamp_ns: int) -> BatteryState:
        """What the battery management reports: the true charge."""
        with self._lock:
            return BatteryState(
                stamp_ns=stamp_ns,
                percentage=self.fraction,
                voltage=self.spec.voltage_v,
                current=-self.power_w / self.spec.voltage_v,
            )

    def summary(self) -> str:
        """The truth for the evaluation, in one line."""
        spec = self.spec
        return (
            f"battery (truth): lowest charge {100 * self.lowest_wh / spec.capacity_wh:.1f} % "
            f"(reserve {100 * spec.reserve:g} %), {self.swaps} swaps; {spec.describe()}"
        )
