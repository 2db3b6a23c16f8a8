"""The base's safety logic and dead reckoning. Pure: no I/O, times in nanoseconds."""

from __future__ import annotations

import math

from common.geo import wrap_angle


class CommandGate:
    """Decides what the wheels get: the newest command, clamped to the limits, or
    zero when the watchdog has expired or an e-stop is asserted."""

    def __init__(self, max_speed: float, max_turn_rate: float, watchdog_ns: int) -> None:
        self.max_speed = max_speed
        self.max_turn_rate = max_turn_rate
        self.watchdog_ns = watchdog_ns
        self._v = 0.0
        self._w = 0.0
        self._last_ns: int | None = None
        self.estop = False
        self.estop_reason = ""

    def command(self, v: float, w: float, now_ns: int) -> None:
        if self.estop:  # commands sent during an e-stop are void, not queued
            return
        self._v = max(-self.max_speed, min(self.max_speed, v))
        self._w = max(-self.max_turn_rate, min(self.max_turn_rate, w))
        self._last_ns = now_ns

    def set_estop(self, asserted: bool, reason: str = "") -> None:
        self.estop = asserted
        self.estop_reason = reason if asserted else ""
        if asserted:  # a released e-stop must not resume an old command
            self._v = self._w = 0.0
            self._last_ns = None

    def hold(self) -> None:
        """Stop now and until a fresh command: the commander is gone, so its last
        command must neither run on until the watchdog nor resume later."""
        self._v = self._w = 0.0
        self._last_ns = None

    def watchdog_tripped(self, now_ns: int) -> bool:
        return self._last_ns is None or now_ns - self._last_ns > self.watchdog_ns

    def output(self, now_ns: int) -> tuple[float, float]:
        if self.estop or self.watchdog_tripped(now_ns):
            return 0.0, 0.0
        return self._v, self._w


class OdometryIntegrator:
    """Integrates body velocities (from the encoders) into a pose in ``odom``
    (midpoint rule, so a constant-curvature arc is followed closely)."""

    def __init__(self) -> None:
        self.x = 0.0
        self.y = 0.0
        self.yaw = 0.0
        self._last_ns: int | None = None

    def update(self, v: float, w: float, stamp_ns: int) -> None:
        if self._last_ns is not None and stamp_ns > self._last_ns:
            dt = (stamp_ns - self._last_ns) / 1e9
            mid = self.yaw + 0.5 * w * dt
            self.x += v * dt * math.cos(mid)
            self.y += v * dt * math.sin(mid)
            self.yaw = float(wrap_angle(self.yaw + w * dt))
        self._last_ns = stamp_ns
