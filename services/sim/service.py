"""The simulator's Zenoh shell: steps the world in sim time, publishes the clock,
ground truth (for evaluation only) and what the simulated devices sense, and renders
scans on request. Time stands still while a scan is rendered: in the world a scan
is measured, not computed."""

from __future__ import annotations

import math
import threading
import time
from pathlib import Path

import msgspec
import numpy as np

from common import keys
from common.clock import NS
from common.field import load_field
from common.messages.base import LaserScan
from common.messages.core import Array
from common.messages.sim import (
    RenderReply,
    RenderRequest,
    SimAntennas,
    SimClock,
    SimEncoders,
    SimWheelCommand,
    TruthPose,
)
from common.service import Context
from common.transport import RequestError
from services.sim.config import SimConfig
from services.sim.lidar import beam_angles
from services.sim.render import write_e57
from services.sim.robot import RobotState
from services.sim.truth_file import ScanTruth, write_truth
from services.sim.world import World


class SimService:
    def __init__(self, ctx: Context, cfg: SimConfig) -> None:
        self.ctx, self.cfg = ctx, cfg
        layout, fld = load_field(ctx.field)
        self.world = World(layout, fld, cfg.world)
        x, y, yaw = cfg.start or (float(fld.origin_xy[0]), float(fld.origin_xy[1]), 0.0)
        self.state = self.world.settle(RobotState(x=x, y=y, yaw=math.radians(yaw)))
        self.rng = np.random.default_rng(cfg.seed)
        self.sim_ns = 0
        self._lock = threading.Lock()  # held while stepping or rendering
        self._cmd: SimWheelCommand | None = None
        self._cmd_ns = -(10**18)
        bus = ctx.bus
        self.clock_pub = bus.publisher(keys.SIM_CLOCK)
        self.truth_pub = bus.publisher(keys.SIM_TRUTH)
        self.ant_pub = bus.publisher(keys.SIM_ANTENNAS)
        self.enc_pub = bus.publisher(keys.SIM_ENCODERS)
        self.lidar_pub = bus.publisher(keys.SIM_LIDAR)
        bus.subscribe(keys.SIM_WHEELS, self._on_wheels)
        bus.serve(keys.SIM_RENDER, self.render)
        angles = beam_angles(cfg.world.lidar)
        self._lidar_meta = (
            float(angles[0]),
            float(angles[-1]),
            float(angles[1] - angles[0]) if len(angles) > 1 else 0.0,
        )

    def _on_wheels(self, cmd: SimWheelCommand) -> None:
        with self._lock:
            self._cmd, self._cmd_ns = cmd, self.sim_ns

    def render(self, req: RenderRequest) -> RenderReply:
        path = Path(req.path)
        if path.suffix != ".e57":
            raise RequestError(f"RenderRequest.path: {req.path!r} is not an .e57 file")
        t0 = time.monotonic()
        with self._lock:  # the world (and its clock) stands still during the scan
            pose = self.world.scanner_pose(self.state)
            settings = msgspec.structs.replace(self.cfg.scan, step_deg=req.step_deg)
            scan = self.world.render_scan(pose, settings, self.rng)
            sd = math.radians(self.cfg.inclinometer_sd_deg)
            pitch = self.state.pitch + float(self.rng.normal(0.0, sd))
            roll = self.state.roll + float(self.rng.normal(0.0, sd))
            path.parent.mkdir(parents=True, exist_ok=True)
            write_e57(path, scan.points, scan.intensity, name=path.stem)
            st = self.state
            # evaluation only: lets `phenorover register` score against the truth
            write_truth(
                path,
                ScanTruth(
                    stamp_ns=self.sim_ns,
                    scanner_pose=pose.tolist(),
                    x=st.x,
                    y=st.y,
                    z=st.z,
                    roll=st.roll,
                    pitch=st.pitch,
                    yaw=st.yaw,
                ),
            )
        return RenderReply(
            stamp_ns=self.sim_ns,
            path=str(path),
            points=len(scan.points),
            pitch=pitch,
            roll=roll,
            render_s=time.monotonic() - t0,
        )

    def _step(self, dt: float) -> None:
        c = self._cmd
        fresh = c is not None and self.sim_ns - self._cmd_ns <= self.cfg.motor_timeout_s * NS
        v, w = (c.v, c.w) if fresh and c is not None else (0.0, 0.0)
        self.state = self.world.step_robot(self.state, v, w, dt, self.rng)
        self.sim_ns += int(dt * NS)

    def _every(self, hz: float, k: int) -> bool:
        n = max(1, round(self.cfg.clock_hz / hz))
        return k % n == 0

    def _publish(self, k: int) -> None:
        s, t = self.state, self.sim_ns
        ev, ew = self.world.encoder_twist(s, self.rng)
        self.enc_pub.put(SimEncoders(stamp_ns=t, frame_id="base_link", v=ev, w=ew))
        if self._every(self.cfg.gnss_hz, k):
            a = self.world.gnss_truth(s).astype(float)
            p1 = (float(a[0, 0]), float(a[0, 1]), float(a[0, 2]))
            p2 = (float(a[1, 0]), float(a[1, 1]), float(a[1, 2]))
            self.ant_pub.put(SimAntennas(stamp_ns=t, frame_id="field", p1=p1, p2=p2))
        if self._every(self.cfg.truth_hz, k):
            self.truth_pub.put(
                TruthPose(
                    stamp_ns=t,
                    frame_id="field",
                    x=s.x,
                    y=s.y,
                    z=s.z,
                    roll=s.roll,
                    pitch=s.pitch,
                    yaw=s.yaw,
                    v=s.v,
                    w=s.w,
                )
            )
        if self._every(self.cfg.lidar_hz, k):
            ranges = self.world.lidar_scan(s, self.rng)
            lo, hi, inc = self._lidar_meta
            lc = self.cfg.world.lidar
            self.lidar_pub.put(
                LaserScan(
                    stamp_ns=t,
                    frame_id="laser",
                    angle_min=lo,
                    angle_max=hi,
                    angle_increment=inc,
                    range_min=lc.min_range,
                    range_max=lc.max_range,
                    ranges=Array.of(ranges),
                )
            )

    def run(self, stop: threading.Event) -> None:
        dt = 1.0 / self.cfg.clock_hz
        wall_dt = dt / self.cfg.real_time_factor
        t_next = time.monotonic()
        k = 0
        while not stop.is_set():
            with self._lock:
                self.clock_pub.put(
                    SimClock(
                        stamp_ns=self.sim_ns,
                        sim_ns=self.sim_ns,
                        real_time_factor=self.cfg.real_time_factor,
                    )
                )
                self._publish(k)
                self._step(dt)
            k += 1
            t_next += wall_dt
            delay = t_next - time.monotonic()
            if delay > 0:
                if stop.wait(delay):
                    break
            elif delay < -1.0:  # fell behind (a render, a slow machine): do not race to catch up
                t_next = time.monotonic()


def build(ctx: Context, cfg: SimConfig) -> SimService:
    return SimService(ctx, cfg)
