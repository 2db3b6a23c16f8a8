"""The robots of the simulated world: each one's true state, noise, battery, IMU and
devices, on its own namespace's keys (:mod:`common.keys`).

One robot (the default) has the plain keys, starts at ``start`` or the field's
Origin and draws its noise from the world's seed. With
``[[services.sim.robots]]`` several robots share the world, robot k (from 1) with
the keys of its ``namespace``, starting at its ``start`` or else at its home beside
the field by the Origin's corner (:func:`common.lanes.homes`, where a plan with
``home`` ``origin`` has it park; a plan's ``near`` homes are given as ``start``), its noise
from its own seed. Each robot's lidar sees the others as boxes of their footprint."""

from __future__ import annotations

import math
import threading

import numpy as np

from common import keys
from common.clock import NS
from common.field import Field
from common.lanes import homes, parked_pose
from common.messages.mission import MissionState
from common.messages.sim import SimWheelCommand
from common.service import Context
from services.sim.battery import SimBattery
from services.sim.config import SimConfig
from services.sim.devices import Devices
from services.sim.faults import FaultSchedule
from services.sim.imu import ImuModel
from services.sim.robot import RobotState
from services.sim.world import World
from services.sim.world_config import BoxObstacle

# a robot's noise seed beside the world's: robot k (from 0) draws from seed + k * this
SEED_STRIDE = 7919


class SimRobot:
    """Robot ``index`` of the world, in ``namespace``: ``lock`` is the world's, held
    while the robot is stepped, read or rendered."""

    def __init__(
        self,
        ctx: Context,
        cfg: SimConfig,
        world: World,
        faults: FaultSchedule,
        index: int,
        namespace: str,
        start: tuple[float, float, float],
        lock: threading.Lock,
    ) -> None:
        self.index, self.namespace, self.lock = index, namespace, lock
        self.cfg, self.world = cfg, world
        x, y, yaw = start
        self.state = world.settle(RobotState(x=x, y=y, yaw=math.radians(yaw)))
        seed = cfg.seed + SEED_STRIDE * index
        self.rng = np.random.default_rng(seed)
        self.imu = ImuModel(cfg.imu, seed, ctx.robot.imu)
        self.battery = SimBattery(ctx.robot.battery, ctx.log)
        self.devices = Devices(ctx, cfg, world, self.imu, faults, self.battery, namespace)
        self._cmd: SimWheelCommand | None = None
        self._cmd_ns = -(10**18)
        self.others: list[SimRobot] = []  # the robots its lidar sees
        self.sim_ns = 0  # before the subscriptions: their callbacks read it
        bus = ctx.bus
        bus.subscribe(keys.SIM_WHEELS.within(namespace), self._on_wheels)
        # the operator who swaps the battery watches the robot's mission
        bus.subscribe(keys.MISSION_STATE.within(namespace), self._on_mission)

    def _on_wheels(self, cmd: SimWheelCommand) -> None:
        with self.lock:
            self._cmd, self._cmd_ns = cmd, self.sim_ns

    def _on_mission(self, state: MissionState) -> None:
        self.battery.on_mission(state)

    def publish(self, k: int, sim_ns: int) -> None:
        """What its devices sense at step ``k`` (the caller holds the world still)."""
        self.sim_ns = sim_ns
        reach = self.cfg.world.lidar.max_range + 2.0  # and a robot's length
        st = self.state
        seen = tuple(
            o.as_obstacle()
            for o in self.others
            if math.hypot(o.state.x - st.x, o.state.y - st.y) < reach
        )
        self.devices.publish(k, st, sim_ns, self.rng, seen)

    def step(self, dt: float, sim_ns: int) -> None:
        """Move under the newest fresh wheel command for ``dt``; ``sim_ns`` after it."""
        c = self._cmd
        fresh = c is not None and self.sim_ns - self._cmd_ns <= self.cfg.motor_timeout_s * NS
        v, w = (c.v, c.w) if fresh and c is not None else (0.0, 0.0)
        if self.battery.empty:  # no power, no drive
            v = w = 0.0
        self.state = self.world.step_robot(self.state, v, w, dt, self.rng)
        self.sim_ns = sim_ns
        st = self.state
        self.battery.step(dt, st.v_wheel, st.w_wheel, sim_ns)

    def as_obstacle(self) -> BoxObstacle:
        """Its body as another robot's lidar sees it: the box around its footprint."""
        fp = self.world.robot.footprint
        c, s = abs(math.cos(self.state.yaw)), abs(math.sin(self.state.yaw))
        return BoxObstacle(
            x=self.state.x,
            y=self.state.y,
            size_x=fp.length * c + fp.width * s,
            size_y=fp.length * s + fp.width * c,
            height=fp.height,
        )


def starts(cfg: SimConfig, field: Field) -> list[tuple[str, tuple[float, float, float]]]:
    """(namespace, start pose) of every robot of the world (see the module docstring).
    ValueError, one line, for namespaces that repeat or a field too small for them."""
    if not cfg.robots:
        x, y = float(field.origin_xy[0]), float(field.origin_xy[1])
        return [("", cfg.start or (x, y, 0.0))]
    names = [r.namespace for r in cfg.robots]
    if len(set(names)) != len(names) or "" in names:
        raise ValueError(f"robots: each needs a namespace of its own, got {names}")
    access, parked = homes(field.cross_lanes_x, field.row_lanes_y, field.origin_xy, len(names))
    out = []
    for r, a, h in zip(cfg.robots, access, parked, strict=True):
        out.append((r.namespace, r.start or parked_pose((h[0], h[1]), (a[0], a[1]))))
    return out
