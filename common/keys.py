"""Every Zenoh key expression phenorover uses, with its message type.

One table, so a subscriber cannot disagree with its publisher about a key or a type.
Keys with ``{placeholders}`` are templates: ``GNSS_FIX.at(antenna=1)``.
``TOPICS`` maps each key to its message type; ``RPCS`` maps each query key to its
(request, reply) types.

Robots sharing a field keep apart by namespace, as ROS 2 robots do: a robot whose
manifest names a ``namespace`` has its own keys (everything but :data:`SITE`) under
``phenorover/<namespace>/``, so ``phenorover/nav/pose`` becomes
``phenorover/rover2/nav/pose``; :func:`in_namespace` says where a key lives and the
bus (:class:`common.transport.Bus`) applies it to everything a service declares. A
robot without one (the default, and every single-robot deployment) keeps the plain
keys.
"""

from __future__ import annotations

import dataclasses
import re
from typing import Any, Generic, TypeVar

from common.messages import base, gnss, mission, nav, plan, scan, sim, system
from common.messages.core import NAMESPACE_PATTERN

PREFIX = "phenorover"

M = TypeVar("M")
Q = TypeVar("Q")
R = TypeVar("R")


@dataclasses.dataclass(frozen=True)
class Topic(Generic[M]):
    """A published stream: its key, message type and delivery class.

    ``bulk`` topics (point clouds, plans) are published with congestion control BLOCK
    so a slow subscriber slows the publisher instead of losing data; ``control``
    topics get Zenoh's real-time priority and DROP, where only the newest value matters.
    ``history`` topics (the mission's events) are published with a cache of that many
    messages and subscribed with history and miss recovery (Zenoh's advanced
    publisher and subscriber): a subscriber that joins late, or whose link was cut,
    receives what it missed once it can reach the publisher again.
    """

    key: str
    type: type[M]
    bulk: bool = False
    control: bool = False
    history: int = 0
    namespaced: bool = dataclasses.field(default=False, compare=False)

    def at(self, **params: Any) -> Topic[M]:
        return dataclasses.replace(self, key=self.key.format(**params))

    def within(self, namespace: str) -> Topic[M]:
        """This topic as the robot in ``namespace`` has it (:func:`in_namespace`); one
        already in a namespace (another robot's, named by a bus of its own) stays there."""
        if self.namespaced or not namespace:
            return self
        return dataclasses.replace(self, key=in_namespace(self.key, namespace), namespaced=True)


@dataclasses.dataclass(frozen=True)
class Rpc(Generic[Q, R]):
    """A query/reply endpoint: the key a service answers on, request and reply types."""

    key: str
    request: Any  # a Struct type or a tagged union of them
    reply: type[R]
    namespaced: bool = dataclasses.field(default=False, compare=False)

    def at(self, **params: Any) -> Rpc[Q, R]:
        return dataclasses.replace(self, key=self.key.format(**params))

    def within(self, namespace: str) -> Rpc[Q, R]:
        """This endpoint as the robot in ``namespace`` has it (:func:`in_namespace`); one
        already in a namespace stays there."""
        if self.namespaced or not namespace:
            return self
        return dataclasses.replace(self, key=in_namespace(self.key, namespace), namespaced=True)


def _k(path: str) -> str:
    return f"{PREFIX}/{path}"


# liveliness tokens: alive/<machine>/<service>/<pid>/<since_ns>
ALIVE = _k("alive/{machine}/{service}/{pid}/{since_ns}")
ALIVE_ALL = _k("alive/**")

HEALTH = Topic(_k("health/{service}"), system.Health)
PING = Rpc[system.Ping, system.Pong](_k("rpc/{service}/ping"), system.Ping, system.Pong)
CONFIG = Rpc[system.ConfigQuery, system.ServiceConfig](
    _k("rpc/{service}/config"), system.ConfigQuery, system.ServiceConfig
)

SIM_CLOCK = Topic(_k("sim/clock"), sim.SimClock, control=True)
# lockstep (common/lockstep.py): each participant's acknowledgement of a step, and
# the liveliness token by which the simulator knows whom to wait for
SIM_ACK = Topic(_k("sim/ack/{service}"), sim.ClockAck, control=True)
LOCKSTEP = _k("sim/lockstep/{service}")
LOCKSTEP_ALL = _k("sim/lockstep/*")
SIM_TRUTH = Topic(_k("sim/truth/pose"), sim.TruthPose)
# the simulated devices' "hardware": read only by the sim backends of gnss, base, scanner
SIM_ANTENNAS = Topic(_k("sim/device/antennas"), sim.SimAntennas)
SIM_WHEELS = Topic(_k("sim/device/wheels"), sim.SimWheelCommand, control=True)
SIM_ENCODERS = Topic(_k("sim/device/encoders"), sim.SimEncoders)
SIM_LIDAR = Topic(_k("sim/device/lidar"), base.LaserScan)
SIM_IMU = Topic(_k("sim/device/imu"), base.Imu)
# the simulated Husky's battery management (its true charge)
SIM_BATTERY = Topic(_k("sim/device/battery"), base.BatteryState)
SIM_RUN = Rpc[sim.SimRun, sim.SimClock](_k("rpc/sim/run"), sim.SimRun, sim.SimClock)
SIM_RENDER = Rpc[sim.RenderRequest, sim.RenderReply](
    _k("rpc/sim/render"), sim.RenderRequest, sim.RenderReply
)

GNSS_FIX = Topic(_k("gnss/{antenna}/fix"), gnss.NavSatFix)
GNSS_HEADING = Topic(_k("gnss/heading"), gnss.GnssHeading)

BASE_CMD_VEL = Topic(_k("base/cmd_vel"), base.Twist, control=True)
BASE_ODOM = Topic(_k("base/odom"), base.Odometry)
BASE_SCAN = Topic(_k("base/scan"), base.LaserScan)
BASE_IMU = Topic(_k("base/imu"), base.Imu)
BASE_ESTOP = Topic(_k("base/estop"), base.EStop, control=True)
BASE_STATUS = Topic(_k("base/status"), base.BaseStatus)
BASE_BATTERY = Topic(_k("base/battery"), base.BatteryState)

NAV_POSE = Topic(_k("nav/pose"), nav.PoseEstimate)
NAV_PROGRESS = Topic(_k("nav/progress"), nav.NavProgress)
NAV_CMD = Rpc[nav.NavCommand, nav.NavReply](_k("rpc/nav/cmd"), nav.NavCommand, nav.NavReply)

SCANNER_STATUS = Topic(_k("scanner/status"), scan.ScannerStatus)
SCANNER_CMD = Rpc[scan.ScannerCommand, scan.ScannerReply](
    _k("rpc/scanner/cmd"), scan.ScannerCommand, scan.ScannerReply
)

PLANNER_PLAN = Rpc[plan.PlanRequest, plan.PlanResult](
    _k("rpc/planner/plan"), plan.PlanRequest, plan.PlanResult
)

MISSION_STATE = Topic(_k("mission/state"), mission.MissionState)
# a survey's events reach the base station even across a cut link: 10,000 events is
# days of surveying (a few per scan location), about 1 MB in the mission's memory
MISSION_EVENT = Topic(_k("mission/event"), mission.MissionEvent, history=10_000)
# the running mission's plan, re-published every few seconds (Zenoh does not latch) for
# late joiners such as the dashboard; not bulk: a dropped copy is replaced by the next
MISSION_PLAN = Topic(_k("mission/plan"), plan.PlanResult)
MISSION_CMD = Rpc[mission.MissionCommand, mission.MissionState](
    _k("rpc/mission/cmd"), mission.MissionCommand, mission.MissionState
)

# robots sharing a field: each mission's lane reservations, asked by the others
FLEET_LANES = Rpc[mission.LaneQuery, mission.LaneClaims](
    _k("rpc/fleet/lanes/{robot}"), mission.LaneQuery, mission.LaneClaims
)

ALL_TOPICS: tuple[Topic[Any], ...] = (
    HEALTH,
    SIM_CLOCK,
    SIM_ACK,
    SIM_TRUTH,
    SIM_ANTENNAS,
    SIM_WHEELS,
    SIM_ENCODERS,
    SIM_LIDAR,
    SIM_IMU,
    SIM_BATTERY,
    GNSS_FIX,
    GNSS_HEADING,
    BASE_CMD_VEL,
    BASE_ODOM,
    BASE_SCAN,
    BASE_IMU,
    BASE_ESTOP,
    BASE_STATUS,
    BASE_BATTERY,
    NAV_POSE,
    NAV_PROGRESS,
    SCANNER_STATUS,
    MISSION_STATE,
    MISSION_EVENT,
    MISSION_PLAN,
)
TOPICS: dict[str, type] = {t.key: t.type for t in ALL_TOPICS}

# What a site shares however many robots survey it: the simulated world's clock, its
# run and its lockstep (participants named ``<namespace>.<service>``), the planner,
# one per base station, and the robots' lane reservations (named by robot).
# Liveliness tokens name their machine already.
SITE: tuple[str, ...] = (
    SIM_CLOCK.key,
    SIM_RUN.key,
    PLANNER_PLAN.key,
    SIM_ACK.key,
    LOCKSTEP,
    FLEET_LANES.key,
)
_SITE_RE = re.compile("|".join(re.sub(r"\\\{[^}]*\\\}", "[^/]+", re.escape(k)) for k in SITE))
NAMESPACE_RE = re.compile(NAMESPACE_PATTERN)  # common.messages.core.Namespace


def in_namespace(key: str, namespace: str) -> str:
    """``key`` as a robot in ``namespace`` uses it: under ``phenorover/<namespace>/``
    unless the key is the site's (:data:`SITE`) or the namespace is empty."""
    if not namespace or _SITE_RE.fullmatch(key) or not key.startswith(PREFIX + "/"):
        return key
    return f"{PREFIX}/{namespace}/{key[len(PREFIX) + 1 :]}"


def participant(name: str, namespace: str) -> str:
    """A service's name where names of every robot meet (lockstep, ``phenorover status``)."""
    return f"{namespace}.{name}" if namespace else name


RPCS: dict[str, tuple[Any, type]] = {
    r.key: (r.request, r.reply)
    for r in (
        PING,
        CONFIG,
        NAV_CMD,
        SCANNER_CMD,
        MISSION_CMD,
        SIM_RENDER,
        SIM_RUN,
        PLANNER_PLAN,
        FLEET_LANES,
    )
}
