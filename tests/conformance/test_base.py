"""The base contract, run against every backend of the base service: ``sim`` (the
simulator's wheels and encoders), ``ros2`` (rmw_zenoh, to the simulated Husky driver
``husky-sim`` as ``make hil`` runs it) and ``ros2-bridge`` (the same driver behind a
stand-in for zenoh-bridge-ros2dds, which maps its ROS topics to plain Zenoh keys).

Whatever the backend: a velocity command reaches the wheels within the robot's limits,
the wheels stop when commands cease (the watchdog) and while an e-stop holds, and the
encoders' motion is published as odometry in the ``odom`` frame. The test plays the
simulator: wheel commands in, encoders out (echoing the wheels while it drives, as the
simulated base would, so that a ROS 2 driver's odometry keeps flowing)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from common import keys
from common.messages.base import BaseStatus, EStop, Odometry, Twist
from common.messages.sim import SimEncoders, SimWheelCommand
from common.robot import default_robot
from common.streams import Publisher
from common.transport import Bus
from services.base.config import BaseConfig
from services.base.ros2 import msgs as ros
from services.base.ros2.node import Ros2Node
from services.base.ros2.types import ODOMETRY, TWIST
from services.base.service import BaseService
from services.base.sim.husky import HuskySim, HuskySimConfig
from tests.conformance.conftest import context, sessions
from tests.conftest import Record, record

BACKENDS = ["sim", "ros2", "ros2-bridge"]
LIMITS = default_robot().limits


def turning_since(n: int) -> Callable[[list[SimWheelCommand]], bool]:
    return lambda ws: any(x.v != 0.0 for x in ws[n:])


def beyond(x: float) -> Callable[[Odometry], bool]:
    return lambda o: o.x > x


@dataclasses.dataclass
class Base:
    backend: str
    cmd: Publisher[Twist]
    estop: Publisher[EStop]
    encoders: Publisher[SimEncoders]
    wheels: Record[SimWheelCommand]
    odom: Record[Odometry]
    status: Record[BaseStatus]
    echo: bool = False  # the simulated base's encoders follow its wheels

    def on_wheels(self, w: SimWheelCommand) -> None:
        self.wheels.add(w)
        if self.echo:
            self.encoders.put(SimEncoders(stamp_ns=w.stamp_ns, v=w.v, w=w.w))

    def drive(self, v: float, w: float = 0.0) -> SimWheelCommand:
        """Command (v, w) until the wheels turn (at what the base made of it)."""
        self.echo = True
        for _ in range(100):
            n = len(self.wheels)
            self.cmd.put(Twist(linear_x=v, angular_z=w))
            if self.wheels.until(turning_since(n), timeout=0.1):
                return next(x for x in self.wheels[n:] if x.v != 0.0)
        pytest.fail(f"{self.backend}: the wheels never turned")

    def more_wheels(self, n: int) -> None:
        """Wait for ``n`` more wheel commands (the base sends them at its rate)."""
        m = len(self.wheels)
        assert self.wheels.until(lambda ws: len(ws) >= m + n, timeout=5.0), self.backend


def bridge(session_bus: Bus) -> Ros2Node:
    """zenoh-bridge-ros2dds' part for the base: ROS 2 ``cmd_vel`` and ``odom`` as the
    plain Zenoh keys of the same names."""
    node = Ros2Node(session_bus.session, "zenoh_bridge_ros2dds")
    cmd = node.publisher("cmd_vel", TWIST)
    session_bus.subscribe_raw("cmd_vel", ros.Twist.deserialize, cmd.put)
    node.subscribe("odom", ODOMETRY, lambda m: session_bus.put_raw("odom", m.serialize()))
    return node


@pytest.fixture(params=BACKENDS)
def base(
    request: pytest.FixtureRequest, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> Iterator[Base]:
    backend: str = request.param
    with sessions(router_endpoint, "husky-sim", "bridge", "base") as (buses, stack, run):
        husky_bus, bridge_bus, base_bus = buses
        rig = Base(
            backend,
            client_bus.publisher(keys.BASE_CMD_VEL),
            client_bus.publisher(keys.BASE_ESTOP),
            client_bus.publisher(keys.SIM_ENCODERS),
            Record(),
            record(client_bus, keys.BASE_ODOM),
            record(client_bus, keys.BASE_STATUS),
        )
        client_bus.subscribe(keys.SIM_WHEELS, rig.on_wheels)
        cfg = BaseConfig(backend="sim")
        if backend != "sim":
            run.start(
                HuskySim(context(husky_bus, "husky-sim", tmp_path), HuskySimConfig()), "husky"
            )
            cfg = BaseConfig(backend="ros2")
        if backend == "ros2-bridge":
            stack.callback(bridge(bridge_bus).close)
            cfg = BaseConfig(backend="ros2", ros2_layout="bridge")
        run.start(BaseService(context(base_bus, "base", tmp_path), cfg), "base")
        assert rig.cmd.wait_matched(timeout=10) and rig.estop.wait_matched(timeout=10)
        yield rig


def test_a_command_reaches_the_wheels_within_the_robots_limits(base: Base) -> None:
    w = base.drive(0.4, 0.1)
    assert (w.v, w.w) == (0.4, 0.1)
    n = len(base.wheels)
    for _ in range(100):
        base.cmd.put(Twist(linear_x=5.0, angular_z=-5.0))
        if base.wheels.until(lambda ws: any(x.v > 0.4 for x in ws[n:]), timeout=0.1):
            break
    fast = next((x for x in base.wheels[n:] if x.v > 0.4), None)
    assert fast is not None and (fast.v, fast.w) == (LIMITS.max_speed, -LIMITS.max_turn_rate)


def test_the_watchdog_stops_the_wheels_when_commands_cease(base: Base) -> None:
    base.drive(0.4)
    n = len(base.wheels)  # then silence
    assert base.wheels.until(lambda ws: any(x.v == 0.0 for x in ws[n:]), timeout=5.0)
    stopped = base.status.wait_for(lambda s: s.stopped_by_watchdog, timeout=5.0)
    assert stopped is not None and not stopped.estop
    m = len(base.wheels)
    base.more_wheels(10)
    assert all((x.v, x.w) == (0.0, 0.0) for x in base.wheels[m:])


def test_an_estop_stops_the_wheels_and_voids_commands_until_released(base: Base) -> None:
    base.drive(0.4)
    base.estop.put(EStop(asserted=True, reason="test"))
    assert base.status.wait_for(lambda s: s.estop, timeout=5.0)
    n = len(base.wheels)
    assert base.wheels.until(lambda ws: any(x.v == 0.0 for x in ws[n:]), timeout=5.0)
    m = len(base.wheels)  # from here every command is void
    for _ in range(10):
        base.cmd.put(Twist(linear_x=0.4))
        base.more_wheels(1)
    base.more_wheels(5)
    assert all((x.v, x.w) == (0.0, 0.0) for x in base.wheels[m:]), base.wheels[m:]
    base.estop.put(EStop(asserted=False))
    assert base.status.wait_for(lambda s: not s.estop, timeout=5.0)
    assert base.drive(0.3).v == 0.3  # a fresh command after the release


def test_the_encoders_motion_is_published_as_odometry(base: Base) -> None:
    for _ in range(100):  # until the encoders' path to base/odom is up
        base.encoders.put(SimEncoders(stamp_ns=0, v=1.0, w=0.0))
        if base.odom.until(bool, timeout=0.1):
            break
    for k in range(1, 11):  # 1 m/s straight for 1 s, one reading at a time
        base.encoders.put(SimEncoders(stamp_ns=k * 100_000_000, v=1.0, w=0.0))
        assert base.odom.wait_for(beyond(0.1 * k - 0.01), timeout=5.0), k
    o = base.odom[-1]
    assert o.frame_id == "odom" and (o.v, o.w) == (1.0, 0.0)
    assert o.x == pytest.approx(1.0, abs=1e-9) and o.y == 0.0 and o.yaw == 0.0
    assert o.var_v > 0 and o.var_w > 0
