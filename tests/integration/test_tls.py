"""Links between machines over mutual TLS: routers with certificates from
``phenorover.certs``, and strangers (no certificate, another CA's) refused."""

from __future__ import annotations

from pathlib import Path

import pytest
import zenoh

from common.config import TlsConfig, zenoh_config
from common.transport import Latest
from phenorover.certs import init_ca, issue_files
from tests.conftest import free_port

MACHINES = ("robot", "jetson", "basestation")


def make_certs(d: Path, machines: tuple[str, ...] = MACHINES) -> dict[str, TlsConfig]:
    """A CA in ``d`` and a certificate per machine, valid on loopback."""
    init_ca(d)
    for m in machines:
        issue_files(m, d, ["localhost", "127.0.0.1"])
    return {
        m: TlsConfig(
            root_ca=str(d / "ca.pem"),
            certificate=str(d / f"{m}.pem"),
            private_key=str(d / f"{m}.key"),
            mutual=True,
        )
        for m in machines
    }


def test_routers_link_over_mutual_tls(tmp_path: Path) -> None:
    tls = make_certs(tmp_path)
    robot_ep = f"tls/localhost:{free_port()}"
    laptop_ep = f"tcp/127.0.0.1:{free_port()}"
    robot = zenoh.open(zenoh_config("router", [robot_ep], [], tls["robot"]))
    laptop = zenoh.open(zenoh_config("router", [laptop_ep], [robot_ep], tls["basestation"]))
    on_robot = zenoh.open(zenoh_config("client", [], [robot_ep], tls["jetson"]))
    on_laptop = zenoh.open(zenoh_config("client", [], [laptop_ep]))
    try:
        got: Latest[bytes] = Latest()
        on_laptop.declare_subscriber("phenorover/test/tls", lambda s: got.put(s.payload.to_bytes()))
        for _ in range(50):  # until the laptop's subscription has reached the robot
            on_robot.put("phenorover/test/tls", b"over tls")
            if got.wait_for(lambda v: True, timeout=0.1):
                break
        assert got.get() == b"over tls"
    finally:
        for s in (on_laptop, on_robot, laptop, robot):
            s.close()


def test_a_tls_router_refuses_no_certificate_and_another_cas(tmp_path: Path) -> None:
    ours, theirs = tmp_path / "ours", tmp_path / "theirs"
    ours.mkdir()
    theirs.mkdir()
    tls = make_certs(ours, ("robot",))
    forged = make_certs(theirs, ("basestation",))["basestation"]  # right name, wrong CA
    robot_ep = f"tls/localhost:{free_port()}"
    robot = zenoh.open(zenoh_config("router", [robot_ep], [], tls["robot"]))
    try:
        no_cert = TlsConfig(root_ca=tls["robot"].root_ca)  # trusts our CA, shows nothing
        # the forger trusts our CA, so only its own certificate can fail the handshake
        forger = TlsConfig(
            root_ca=tls["robot"].root_ca,
            certificate=forged.certificate,
            private_key=forged.private_key,
            mutual=True,
        )
        for stranger in (no_cert, forger):
            with pytest.raises(zenoh.ZError):
                zenoh.open(zenoh_config("client", [], [robot_ep], stranger, client_timeout_s=1.0))
    finally:
        robot.close()
