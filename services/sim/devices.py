"""What the simulated devices sense, published each step of the world: encoders,
the antennas' true positions (with the sky the crop hides), the IMU, the 2D lidar,
the battery's charge (1 Hz) and the true pose (for evaluation only). Faults change
what the devices report, never the truth."""

from __future__ import annotations

import logging

import numpy as np

from common import keys
from common.clock import NS
from common.messages.base import LaserScan
from common.messages.core import BASE_FRAME, FIELD_FRAME, LASER_FRAME, Array
from common.messages.sim import SimAntennas, SimEncoders, TruthPose
from common.service import Context
from services.sim.battery import SimBattery
from services.sim.config import SimConfig
from services.sim.faults import FaultSchedule, describe
from services.sim.imu import ImuModel
from services.sim.lidar import beam_angles
from services.sim.robot import RobotState
from services.sim.world import World
from services.sim.world_config import BoxObstacle


class Devices:
    def __init__(
        self,
        ctx: Context,
        cfg: SimConfig,
        world: World,
        imu: ImuModel,
        faults: FaultSchedule,
        battery: SimBattery,
        namespace: str = "",
    ) -> None:
        self.cfg, self.world, self.imu, self.faults = cfg, world, imu, faults
        self.battery = battery
        self.log: logging.Logger = ctx.log
        bus, ns = ctx.bus, namespace  # the robot's devices, on its keys
        self.truth_pub = bus.publisher(keys.SIM_TRUTH.within(ns))
        self.ant_pub = bus.publisher(keys.SIM_ANTENNAS.within(ns))
        self.enc_pub = bus.publisher(keys.SIM_ENCODERS.within(ns))
        self.lidar_pub = bus.publisher(keys.SIM_LIDAR.within(ns))
        self.imu_pub = bus.publisher(keys.SIM_IMU.within(ns))
        self.battery_pub = bus.publisher(keys.SIM_BATTERY.within(ns))
        angles = beam_angles(cfg.world.lidar)
        self._lidar_meta = (
            float(angles[0]),
            float(angles[-1]),
            float(angles[1] - angles[0]) if len(angles) > 1 else 0.0,
        )

    def _every(self, hz: float, k: int) -> bool:
        n = max(1, round(self.cfg.clock_hz / hz))
        return k % n == 0

    def publish(
        self,
        k: int,
        s: RobotState,
        t: int,
        rng: np.random.Generator,
        others: tuple[BoxObstacle, ...] = (),
    ) -> None:
        """What the devices sense at step ``k`` (sim time ``t``, the robot in ``s``);
        the noise drawn from ``rng`` in a fixed order. ``others``: the other robots'
        bodies, which the lidar sees."""
        for fault, started in self.faults.changes(t / NS):
            self.log.warning("%s", describe(fault, started))
        fx = self.faults.effects(t / NS)
        # faults change what the devices report only: the same random numbers are
        # drawn either way, so the true motion does not depend on them
        ev, ew = self.world.encoder_twist(s, rng)
        if fx.encoders == "zero":
            ev = ew = 0.0
        if fx.encoders != "silent":
            self.enc_pub.put(SimEncoders(stamp_ns=t, frame_id=BASE_FRAME, v=ev, w=ew))
        if self._every(self.cfg.gnss_hz, k):
            a = self.world.gnss_truth(s).astype(float)
            blocked = self.world.sky_blocked(a)
            self.ant_pub.put(
                SimAntennas(
                    stamp_ns=t,
                    frame_id=FIELD_FRAME,
                    p1=(float(a[0, 0]), float(a[0, 1]), float(a[0, 2])),
                    p2=(float(a[1, 0]), float(a[1, 1]), float(a[1, 2])),
                    outage1=fx.outage[0],
                    outage2=fx.outage[1],
                    force_float1=fx.force_float[0],
                    force_float2=fx.force_float[1],
                    offset1=fx.offset[0],
                    offset2=fx.offset[1],
                    blocked1=blocked[0],
                    blocked2=blocked[1],
                )
            )
        if self._every(1.0, k):
            self.battery_pub.put(self.battery.message(t))
        if self.cfg.imu.enabled and self._every(self.cfg.imu.rate_hz, k):
            self.imu_pub.put(self.imu.read(t / NS, s))
        if self._every(self.cfg.truth_hz, k):
            self.truth_pub.put(
                TruthPose(
                    stamp_ns=t,
                    frame_id=FIELD_FRAME,
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
            ranges = self.world.lidar_scan(s, rng, (*fx.obstacles, *others))
            lo, hi, inc = self._lidar_meta
            lc = self.cfg.world.lidar
            self.lidar_pub.put(
                LaserScan(
                    stamp_ns=t,
                    frame_id=LASER_FRAME,
                    angle_min=lo,
                    angle_max=hi,
                    angle_increment=inc,
                    range_min=lc.min_range,
                    range_max=lc.max_range,
                    ranges=Array.of(ranges),
                )
            )
