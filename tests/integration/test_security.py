"""Access control between machines: each remote machine, known by its certificate,
may send only what its role allows; denials are logged; the policy covers every key."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from common import keys
from common.acl import EVERYONE, ROLES, SIMULATION_ONLY, key_expr, may_send, router_acl
from common.acl_log import DenialLog, parse_denial
from common.config import AccessConfig, TlsConfig, zenoh_config
from common.messages.mission import MissionEvent
from common.transport import Bus
from phenorover.certs import issue_files
from phenorover.preflight import validate
from phenorover.router import router_config
from tests.conftest import REPO, Procs, free_port, record
from tests.integration.test_tls import make_certs

HEALTH = "phenorover/health/probe"  # every machine may publish health: the marker


def robot_manifest(d: Path, tls: TlsConfig, remote: int, local: int) -> Path:
    m = d / "robot.toml"
    m.write_text(f"""machine = "robot"
[zenoh]
listen = ["tcp/127.0.0.1:{local}", "tls/localhost:{remote}"]
[zenoh.tls]
root_ca = "{tls.root_ca}"
certificate = "{tls.certificate}"
private_key = "{tls.private_key}"
mutual = true
[zenoh.access]
remotes = {{ jetson = "jetson", basestation = "basestation" }}
""")
    return m


class Robot:
    """What the robot's own processes see: a client on the robot router's loopback port
    recording every cmd_vel and health sample and every mission and scanner query."""

    def __init__(self, local_ep: str) -> None:
        self.session = zenoh.open(zenoh_config("client", [], [local_ep]))
        self.seen: list[str] = []
        self._cv = threading.Condition()
        # One subscriber for both: zenoh-python runs each callback on its own thread,
        # so only one subscriber sees a link's samples in the order they were sent.
        wanted = (keys.BASE_CMD_VEL.key, "phenorover/health/")
        self.session.declare_subscriber(
            "phenorover/**",
            lambda s: self._saw(k) if (k := str(s.key_expr)).startswith(wanted) else None,
        )
        for key in (keys.MISSION_CMD.key, keys.SCANNER_CMD.key):
            self.session.declare_queryable(key, self._answer)

    def _saw(self, key: str) -> None:
        with self._cv:
            self.seen.append(key)
            self._cv.notify_all()

    def _answer(self, q: zenoh.Query) -> None:
        self._saw(str(q.key_expr))
        q.reply(q.key_expr, b"ok")

    def wait_for(self, key: str, timeout: float = 5.0) -> bool:
        with self._cv:
            return self._cv.wait_for(lambda: key in self.seen, timeout=timeout)


def send(session: zenoh.Session, robot: Robot, put: str) -> bool:
    """Put on ``put``, then the health marker on the same link; once the marker is in,
    ``put`` has arrived if it ever will (one link delivers in order). Delivered?"""
    robot.seen.clear()
    for _ in range(50):  # until the robot's subscriptions have reached this session
        session.put(put, b"x")
        session.put(HEALTH, b"x")
        if robot.wait_for(HEALTH, timeout=0.1):
            break
    assert HEALTH in robot.seen, "not even the marker was delivered"
    return put in robot.seen


def call(session: zenoh.Session, key: str) -> bool:
    """Whether a query on ``key`` was answered (a denied one reaches nobody)."""
    replies = session.get(key, target=zenoh.QueryTarget.ALL, timeout=1.0)
    return any(r.ok is not None for r in replies)


@pytest.fixture
def deployment(tmp_path: Path) -> Iterator[tuple[dict[str, TlsConfig], str, Robot]]:
    tls = make_certs(tmp_path)
    remote, local = free_port(), free_port()
    manifest = validate(robot_manifest(tmp_path, tls["robot"], remote, local))
    router = zenoh.open(router_config(manifest))
    robot = Robot(f"tcp/127.0.0.1:{local}")
    yield tls, f"tls/localhost:{remote}", robot
    robot.session.close()
    router.close()


@pytest.mark.parametrize(
    ("machine", "cmd_vel", "mission", "scanner"),
    [("basestation", False, True, False), ("jetson", False, False, False)],
)
def test_a_machine_sends_only_what_its_role_allows(
    deployment: tuple[dict[str, TlsConfig], str, Robot],
    machine: str,
    cmd_vel: bool,
    mission: bool,
    scanner: bool,
) -> None:
    tls, remote_ep, robot = deployment
    with zenoh.open(zenoh_config("client", [], [remote_ep], tls[machine])) as s:
        assert send(s, robot, keys.BASE_CMD_VEL.key) is cmd_vel
        assert call(s, keys.MISSION_CMD.key) is mission
        assert call(s, keys.SCANNER_CMD.key) is scanner
    assert may_send(machine, "put", keys.BASE_CMD_VEL.key) is cmd_vel  # type: ignore[arg-type]


def test_the_robots_own_processes_may_do_anything(
    deployment: tuple[dict[str, TlsConfig], str, Robot],
) -> None:
    _, _, robot = deployment
    assert send(robot.session, robot, keys.BASE_CMD_VEL.key)
    assert call(robot.session, keys.MISSION_CMD.key)


def test_a_certificate_from_our_ca_with_an_unknown_name_can_do_nothing(
    deployment: tuple[dict[str, TlsConfig], str, Robot],
) -> None:
    tls, remote_ep, robot = deployment
    ca_dir = Path(tls["robot"].root_ca).parent
    issue_files("laptop", ca_dir, ["localhost"])
    laptop = TlsConfig(
        root_ca=str(ca_dir / "ca.pem"),
        certificate=str(ca_dir / "laptop.pem"),
        private_key=str(ca_dir / "laptop.key"),
        mutual=True,
    )
    with zenoh.open(zenoh_config("client", [], [remote_ep], laptop)) as s:
        s.put(HEALTH, b"x")
        # the put went first on the same link: by the query's timeout it would be in
        assert not call(s, keys.MISSION_CMD.key)
    assert robot.seen == []


def test_a_machine_declares_liveliness_only_under_its_own_name(
    deployment: tuple[dict[str, TlsConfig], str, Robot],
) -> None:
    tls, remote_ep, robot = deployment
    fake, own = "phenorover/alive/robot/nav/1/1", "phenorover/alive/basestation/viz/2/2"
    with zenoh.open(zenoh_config("client", [], [remote_ep], tls["basestation"])) as s:
        tokens = [s.liveliness().declare_token(k) for k in (fake, own)]  # fake goes first
        seen: set[str] = set()
        for _ in range(50):
            replies = robot.session.liveliness().get("phenorover/alive/**", timeout=0.2)
            seen = {str(r.ok.key_expr) for r in replies if r.ok is not None}
            if own in seen:
                break
        assert own in seen and fake not in seen
        for t in tokens:
            t.undeclare()


def test_the_jetson_behind_the_hub_serves_the_robot_and_nobody_else(
    deployment: tuple[dict[str, TlsConfig], str, Robot],
) -> None:
    tls, remote_ep, robot = deployment
    jetson_ep = f"tcp/127.0.0.1:{free_port()}"
    hub = router_acl(AccessConfig(remotes={"robot": "hub"}))
    jetson = zenoh.open(
        zenoh_config("router", [jetson_ep], [remote_ep], tls["jetson"], access_control=hub)
    )
    scanner = Robot(jetson_ep)  # the scanner's side, on the Jetson's loopback
    try:
        assert scanner.session.info.routers_zid()
        for _ in range(50):  # until the Jetson's queryable is known at the robot
            call(robot.session, keys.SCANNER_CMD.key)  # answered by both: target ALL
            if scanner.wait_for(keys.SCANNER_CMD.key, timeout=0):
                break
        assert keys.SCANNER_CMD.key in scanner.seen
        with zenoh.open(zenoh_config("client", [], [remote_ep], tls["basestation"])) as s:
            scanner.seen.clear()
            assert not call(s, keys.SCANNER_CMD.key)
            assert call(s, keys.MISSION_CMD.key)  # the base station does reach the robot
        assert keys.SCANNER_CMD.key not in scanner.seen
    finally:
        scanner.session.close()
        jetson.close()


def test_the_launcher_enforces_and_logs_denials(tmp_path: Path, procs: Procs) -> None:
    tls = make_certs(tmp_path)
    remote, local = free_port(), free_port()
    manifest = robot_manifest(tmp_path, tls["robot"], remote, local)
    err = tmp_path / "up.log"
    up = procs.start("-m", "phenorover", "up", str(manifest), log=err)
    robot = Robot(f"tcp/127.0.0.1:{local}")  # waits for the launcher's router
    try:
        with zenoh.open(
            zenoh_config("client", [], [f"tls/localhost:{remote}"], tls["basestation"])
        ) as s:
            assert not send(s, robot, keys.BASE_CMD_VEL.key)
            assert not send(s, robot, keys.BASE_CMD_VEL.key)  # again: logged once
    finally:
        robot.session.close()
    up.send_signal(signal.SIGTERM)
    assert up.wait(timeout=10) == 0
    lines = err.read_text().splitlines()
    denied = [ln for ln in lines if "denied:" in ln]
    assert len(denied) == 1, lines
    assert "basestation may not Put (ingress) on phenorover/base/cmd_vel" in denied[0]
    assert not [ln for ln in lines if "is authorized" in ln], "the allowed traffic leaked out"


def test_every_key_is_granted_to_a_role_or_simulation_only() -> None:
    granted = {e for g in ROLES.values() for e in (*g.publishes, *g.calls, *g.serves)}
    for key in [*keys.TOPICS, *keys.RPCS]:
        ke = key_expr(key)
        assert (
            ke in granted
            or ke in SIMULATION_ONLY
            or ke in {*EVERYONE.publishes, *EVERYONE.calls, *EVERYONE.serves}
        ), f"{key}: decide who may send it (common/acl.py)"


def test_the_policy_matches_the_issue() -> None:
    vel, mission, plan = keys.BASE_CMD_VEL.key, keys.MISSION_CMD.key, keys.PLANNER_PLAN.key
    assert [r for r in ("robot", "jetson", "basestation") if may_send(r, "put", vel)] == ["robot"]
    assert not may_send("basestation", "put", keys.BASE_ESTOP.key)
    assert [r for r in ("robot", "jetson", "basestation") if may_send(r, "query", mission)] == [
        "robot",
        "basestation",
    ]
    assert not may_send("jetson", "query", plan)
    assert not may_send("basestation", "query", keys.NAV_CMD.key)
    assert may_send("jetson", "put", "phenorover/health/scanner")
    assert may_send("jetson", "query", "phenorover/rpc/mission/ping")
    assert not may_send("basestation", "put", keys.SIM_WHEELS.key)


def test_a_router_with_access_control_starts() -> None:
    acl = router_acl(AccessConfig(remotes={"robot": "hub"}))
    ep = f"tcp/127.0.0.1:{free_port()}"
    zenoh.open(zenoh_config("router", [ep], [], access_control=acl)).close()


def test_denial_log_reports_each_kind_once_then_counts() -> None:
    out: list[str] = []
    log = DenialLog(out.append, every_s=10.0)
    line = (
        "\x1b[2m2026\x1b[0m TRACE rx-1 zenoh::net::routing::interceptor::access_control: "
        "ae60 on Interface(lo)+CertCommonName(basestation)+Transport(Tls)+ae60 is "
        "unauthorized to Put (ingress) on phenorover/base/cmd_vel"
    )
    allowed = line.replace("unauthorized", "authorized")
    assert log.feed(allowed, 0.0) and not out
    assert not log.feed("something else entirely", 0.0)
    for t in (0.0, 1.0, 2.0):
        assert log.feed(line, t)
    assert out == ["denied: basestation may not Put (ingress) on phenorover/base/cmd_vel"]
    log.feed(line, 12.0)
    assert out[-1].endswith("(2 more since)")
    assert parse_denial(allowed) is None


def test_up_check_says_what_tls_would_use_and_finds_a_stranger_certificate(
    tmp_path: Path,
) -> None:
    tls = make_certs(tmp_path)
    m = robot_manifest(tmp_path, tls["jetson"], free_port(), free_port())  # wrong machine
    r = subprocess.run(
        [sys.executable, "-m", "phenorover", "up", "--check", str(m)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2
    assert "mutual TLS with" in r.stdout
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "common name 'jetson', not the machine 'robot'" in lines[0]


def test_the_base_station_gets_the_missions_events_with_their_history(
    deployment: tuple[dict[str, TlsConfig], str, Robot],
) -> None:
    """History topics travel under ``<key>/@adv/...`` too, which ``**`` never matches:
    the policy must let the base station ask the robot's cache and hear its heartbeats."""
    tls, remote_ep, robot = deployment
    mission = Bus(robot.session, "mission")
    pub = mission.publisher(keys.MISSION_EVENT)
    pub.put(MissionEvent(mission="m", level="info", text="before the base station"))
    with zenoh.open(zenoh_config("client", [], [remote_ep], tls["basestation"])) as s:
        viz = Bus(s, "viz")
        events = record(viz, keys.MISSION_EVENT)
        assert events.wait_for(lambda e: e.text == "before the base station", timeout=10)
        pub.put(MissionEvent(mission="m", level="info", text="live"))
        assert events.wait_for(lambda e: e.text == "live", timeout=10)
        viz.close()
    mission.close()
