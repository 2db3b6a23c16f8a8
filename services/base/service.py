"""The base service's Zenoh shell: velocity commands in (through the watchdog and the
e-stop), wheel odometry, the IMU, lidar, the battery's state and status out."""

from __future__ import annotations

import threading

from common import clock as clk
from common import keys
from common.messages.base import BaseStatus, EStop, LaserScan, Odometry, Twist
from common.messages.core import ODOM_FRAME
from common.service import Context
from common.status import parse_token
from services.base.backends import BACKENDS, Sinks
from services.base.config import BaseConfig
from services.base.drive import CommandGate, OdometryIntegrator


class BaseService:
    def __init__(self, ctx: Context, cfg: BaseConfig) -> None:
        self.ctx, self.cfg = ctx, cfg
        lim = ctx.robot.limits
        self.gate = CommandGate(lim.max_speed, lim.max_turn_rate, int(cfg.watchdog_s * 1e9))
        self.odom = OdometryIntegrator()
        self._lock = threading.Lock()
        self.odom_pub = ctx.bus.publisher(keys.BASE_ODOM)
        self.scan_pub = ctx.bus.publisher(keys.BASE_SCAN)
        self.imu_pub = ctx.bus.publisher(keys.BASE_IMU)
        self.status_pub = ctx.bus.publisher(keys.BASE_STATUS)
        self.battery_pub = ctx.bus.publisher(keys.BASE_BATTERY)
        sinks = Sinks(
            encoders=self._on_encoders,
            odom=self._on_odom,
            scan=self._on_scan,
            imu=self.imu_pub.put,
            battery=self.battery_pub.put,
        )
        self.drive = BACKENDS[cfg.backend](cfg, ctx.bus, sinks)
        ctx.bus.subscribe(keys.BASE_CMD_VEL, self._on_cmd)
        ctx.bus.subscribe(keys.BASE_ESTOP, self._on_estop)
        self._commanders: set[str] = set()  # liveliness tokens of the commander
        # the last commander is gone: its commands still in flight (delivered on
        # another thread than its token's end) are void until a commander is back
        self._orphaned = False
        ctx.bus.watch_alive(self._on_alive)

    # Every send to the wheels is made under the lock, so a stop (e-stop, commander
    # gone) is never followed by a command computed before it on another thread.
    def _on_cmd(self, t: Twist) -> None:
        now = self.ctx.clock.now_ns()
        with self._lock:
            if self._orphaned:
                return
            self.gate.command(t.linear_x, t.angular_z, now)
            v, w = self.gate.output(now)
            if v == 0.0 and w == 0.0:  # a stop goes to the wheels now, not at the next tick
                self.drive.send(0.0, 0.0, now)

    def _on_estop(self, e: EStop) -> None:
        with self._lock:
            if e.asserted != self.gate.estop:
                self.ctx.log.warning(
                    "e-stop %s %s", "asserted" if e.asserted else "released", e.reason
                )
            self.gate.set_estop(e.asserted, e.reason)
            if e.asserted:
                self.drive.send(0.0, 0.0, self.ctx.clock.now_ns())

    def _on_alive(self, token: str, alive: bool) -> None:
        a = parse_token(token)
        if a is None or a.service != self.cfg.commander:
            return
        if alive:
            with self._lock:
                self._commanders.add(token)
                self._orphaned = False
            return
        if token not in self._commanders:
            return
        now = self.ctx.clock.now_ns()
        with self._lock:
            self._commanders.discard(token)
            self._orphaned = not self._commanders
            moving = self.gate.output(now) != (0.0, 0.0)
            self.gate.hold()
            self.drive.send(0.0, 0.0, now)
        if moving:
            self.ctx.log.warning("%s is gone (%s): wheels stopped", a.service, a.machine)

    def _on_encoders(self, stamp_ns: int, v: float, w: float) -> None:
        with self._lock:
            self.odom.update(v, w, stamp_ns)
            x, y, yaw = self.odom.x, self.odom.y, self.odom.yaw
        self._on_odom(stamp_ns, x, y, yaw, v, w)

    def _on_odom(self, stamp_ns: int, x: float, y: float, yaw: float, v: float, w: float) -> None:
        self.odom_pub.put(
            Odometry(
                stamp_ns=stamp_ns,
                frame_id=ODOM_FRAME,
                x=x,
                y=y,
                yaw=yaw,
                v=v,
                w=w,
                var_v=self.cfg.var_v,
                var_w=self.cfg.var_w + (self.cfg.turn_slip_sd * w) ** 2,
            )
        )

    def _on_scan(self, scan: LaserScan) -> None:
        self.scan_pub.put(scan)

    def run(self, stop: threading.Event) -> None:
        tripped = True
        for now in clk.ticks(self.ctx.clock, self.cfg.rate_hz, stop):
            with self._lock:
                v, w = self.gate.output(now)
                wd = self.gate.watchdog_tripped(now)
                estop = self.gate.estop
                self.drive.send(v, w, now)
            if wd and not tripped and not estop:
                self.ctx.log.info(
                    "watchdog: no command for %.1f s, wheels stopped", self.cfg.watchdog_s
                )
            tripped = wd
            self.status_pub.put(BaseStatus(stamp_ns=now, stopped_by_watchdog=wd, estop=estop))
        self.drive.send(0.0, 0.0, self.ctx.clock.now_ns())


def build(ctx: Context, cfg: BaseConfig) -> BaseService:
    return BaseService(ctx, cfg)
