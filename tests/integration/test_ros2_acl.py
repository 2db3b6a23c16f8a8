"""The robot's ROS 2 driver and our base under the shipped robot manifest's access
control: the router is made from ``deploy/robot.toml``'s ``[zenoh.access]`` and its
``[services.base]`` (Clearpath's Jazzy layout), the base service runs that section, and
a ROS 2 peer we did not write (zenoh-ros2-sdk) plays the driver: it publishes
Odometry on ``/a200_0000/platform/odom``, takes TwistStamped on ``/a200_0000/cmd_vel``,
and each side discovers the other's endpoints from rmw_zenoh's liveliness tokens.

rmw_zenoh's default session is a peer that meshes with the other peers on the machine
(gossip), so the router is not in its path; a node in client mode, or one the router
relays for, goes through the router: both are run. Without the ``@ros2_lv`` rule the
router denies discovery to the client while data still flows (data keys are under
``**``)."""

from __future__ import annotations

import threading
import tomllib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import tomli_w
import zenoh
import zenoh_ros2_sdk.message_registry as sdk_registry
from zenoh_ros2_sdk import ROS2Publisher, ROS2Subscriber
from zenoh_ros2_sdk.session import ZenohSession

from common import keys
from common.acl import router_acl
from common.client import wait_alive
from common.config import zenoh_config
from common.messages.base import Twist
from common.transport import Bus
from phenorover.preflight import validate
from phenorover.router import ros2_domains, router_config
from services.base.ros2.wire import dds_type_name
from tests.conftest import REPO, Procs, free_port, record
from tests.integration.test_tls import make_certs

MSGS = REPO / "tests" / "data" / "ros2_msgs"
SHIPPED = tomllib.loads((REPO / "deploy" / "robot.toml").read_text())
BASE = SHIPPED["services"]["base"]
NS = BASE["ros2_namespace"]


def fq(topic: str) -> str:
    return f"{NS}/{topic}"


def robot_manifest(d: Path, local: int) -> Path:
    """The shipped robot manifest's access control and base, on loopback ports and the
    test's certificates (its other services need devices this machine lacks)."""
    tls = make_certs(d)["robot"]
    m = {
        "machine": "robot",
        "zenoh": {
            "local": [f"tcp/127.0.0.1:{local}"],
            "listen": [f"tcp/127.0.0.1:{local}", f"tls/localhost:{free_port()}"],
            "tls": {
                "root_ca": tls.root_ca,
                "certificate": tls.certificate,
                "private_key": tls.private_key,
                "mutual": True,
            },
            "access": SHIPPED["zenoh"]["access"],
        },
        "services": {"base": BASE},
    }
    path = d / "robot.toml"
    path.write_text(tomli_w.dumps(m))
    return path


@pytest.fixture
def sdk(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The SDK's process-wide session is made afresh by each test (its mode set by
    ZENOH_CONFIG_OVERRIDE), reading .msg files from tests/data."""
    sdk_registry._registry = None
    sdk_registry.get_registry(str(MSGS))
    ZenohSession._instance = None
    yield
    if ZenohSession._instance is not None:
        ZenohSession._instance.close()
    ZenohSession._instance = None
    sdk_registry._registry = None


def _odometry(t: dict[str, Any], k: int) -> dict[str, Any]:
    vec, quat = t["geometry_msgs/msg/Vector3"], t["geometry_msgs/msg/Quaternion"]
    pose = t["geometry_msgs/msg/Pose"](
        position=t["geometry_msgs/msg/Point"](x=1.0 + k, y=2.0, z=0.0),
        orientation=quat(x=0.0, y=0.0, z=0.0, w=1.0),
    )
    tw = t["geometry_msgs/msg/Twist"](
        linear=vec(x=0.3, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0)
    )
    stamp = t["builtin_interfaces/msg/Time"](sec=100 + k, nanosec=0)
    return {
        "header": t["std_msgs/msg/Header"](stamp=stamp, frame_id="odom"),
        "child_frame_id": "base_link",
        "pose": t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
        "twist": t["geometry_msgs/msg/TwistWithCovariance"](twist=tw, covariance=np.zeros(36)),
    }


def _publisher_token(key: str, topic: str, ros_type: str) -> bool:
    """Whether liveliness key ``key`` is rmw_zenoh's token of a publisher (``MP``) of
    ``topic``. Each side asks for the *other* side's publisher: its own subscription's
    token would answer too."""
    want = "/" + topic.replace("/", "%") + "/" + dds_type_name(ros_type) + "/"
    return "/MP/" in key and want in key


def _sees_publisher(session: zenoh.Session, topic: str, ros_type: str) -> bool:
    """Whether ``session`` discovers a publisher of ``topic`` by rmw_zenoh's start-up
    liveliness query."""
    replies = session.liveliness().get(f"@ros2_lv/{BASE['ros2_domain']}/**", timeout=1.0)
    return any(
        r.ok is not None and _publisher_token(str(r.ok.key_expr), topic, ros_type) for r in replies
    )


class _Publishers:
    """The rmw_zenoh endpoint tokens ``session`` discovers, as a ROS 2 graph cache
    does: a liveliness subscriber with history (the tokens alive already, then each
    new one)."""

    def __init__(self, session: zenoh.Session) -> None:
        self._session = session
        self._keys: list[str] = []
        self._cond = threading.Condition()

    def _on(self, s: zenoh.Sample) -> None:
        if s.kind == zenoh.SampleKind.PUT:
            with self._cond:
                self._keys.append(str(s.key_expr))
                self._cond.notify_all()

    def __enter__(self) -> _Publishers:
        key = f"@ros2_lv/{BASE['ros2_domain']}/**"
        self._sub = self._session.liveliness().declare_subscriber(key, self._on, history=True)
        return self

    def __exit__(self, *_: object) -> None:
        self._sub.undeclare()

    def wait_for(self, topic: str, ros_type: str, timeout: float = 20.0) -> bool:
        with self._cond:
            return self._cond.wait_for(
                lambda: any(_publisher_token(k, topic, ros_type) for k in self._keys), timeout
            )


@pytest.mark.parametrize(
    ("sdk_mode", "ros2_rule"),
    [("peer", True), ("client", True), ("client", False)],
    ids=["peer", "client", "client-without-ros2_lv-rule"],
)
def test_husky_driver_and_base_under_the_shipped_access_control(
    procs: Procs,
    tmp_path: Path,
    sdk: None,
    monkeypatch: pytest.MonkeyPatch,
    sdk_mode: str,
    ros2_rule: bool,
) -> None:
    local = free_port()
    path = robot_manifest(tmp_path, local)
    manifest = validate(path)
    assert manifest.zenoh.access is not None and ros2_domains(manifest) == [0]
    if ros2_rule:
        conf = router_config(manifest)  # exactly what `phenorover up` opens
    else:
        acl = router_acl(manifest.zenoh.access, ros2_domains(manifest))
        for rule in acl["rules"]:
            rule["key_exprs"] = [e for e in rule["key_exprs"] if not e.startswith("@ros2_lv")]
        zs = manifest.zenoh
        conf = zenoh_config("router", zs.listen, [], zs.tls, access_control=acl)
    ep = f"tcp/127.0.0.1:{local}"
    override = 'listen/endpoints=["tcp/127.0.0.1:0"]'
    if sdk_mode == "client":
        override += ';mode="client"'
    monkeypatch.setenv("ZENOH_CONFIG_OVERRIDE", override)
    with zenoh.open(conf) as _router, zenoh.open(zenoh_config("peer", [], [ep])) as robot:
        bus = Bus(robot, "test")
        odom = record(bus, keys.BASE_ODOM)
        procs.service("services.base", ep, "--manifest", str(path), log=tmp_path / "base.log")
        assert wait_alive(robot, {"base"}, timeout=20)

        odom_pub = ROS2Publisher(fq("platform/odom"), "nav_msgs/msg/Odometry", router_port=local)
        twists: list[Any] = []
        got = threading.Condition()

        def on_twist(m: Any) -> None:
            with got:
                twists.append(m)
                got.notify_all()

        sub = ROS2Subscriber(
            fq("cmd_vel"), "geometry_msgs/msg/TwistStamped", on_twist, router_port=local
        )
        types = ZenohSession.get_instance().store.types
        stop = threading.Event()

        def driver() -> None:  # the driver's odometry at 20 Hz: the test's input
            k = 0
            while not stop.wait(0.05):
                odom_pub.publish(**_odometry(types, k))
                k += 1

        feeder = threading.Thread(target=driver, daemon=True)
        feeder.start()
        try:
            # odometry in
            o = odom.wait_for(lambda o: o.x >= 1.0, timeout=15.0)
            assert o is not None, "the base never turned the driver's odometry into base/odom"
            assert (o.y, o.v) == (2.0, 0.3)
            # commands out, as TwistStamped with the stamp and frame filled
            cmd = bus.publisher(keys.BASE_CMD_VEL)
            with got:
                for _ in range(100):
                    cmd.put(Twist(linear_x=0.4, angular_z=0.2))
                    if got.wait_for(lambda: any(m.twist.linear.x == 0.4 for m in twists), 0.1):
                        break
            m = next((m for m in twists if m.twist.linear.x == 0.4), None)
            assert m is not None, "the driver never received a TwistStamped on cmd_vel"
            assert m.twist.angular.z == 0.2 and m.header.frame_id == "base_link"
            assert m.header.stamp.sec > 0  # diff_drive_controller would take 0 as "now"

            # discovery, both ways: each side's graph cache as rmw_zenoh builds it (a
            # liveliness subscriber with history), waited for on the tokens' arrival
            sdk_session = ZenohSession.get_instance().session
            ours = (fq("cmd_vel"), "geometry_msgs/msg/TwistStamped")
            theirs = (fq("platform/odom"), "nav_msgs/msg/Odometry")
            if ros2_rule:
                with (
                    _Publishers(sdk_session) as driver_sees,
                    _Publishers(robot) as we_see,
                ):
                    seen = (driver_sees.wait_for(*ours), we_see.wait_for(*theirs))
                assert seen == (True, True), f"discovery (driver sees us, we see it): {seen}"
            else:
                seen = (
                    _sees_publisher(sdk_session, *ours),
                    _sees_publisher(robot, *theirs),
                )
                assert seen == (False, False), f"discovery passed the router: {seen}"
        finally:
            stop.set()
            feeder.join()
            odom_pub.close()
            sub.close()
