"""Links between machines over mutual TLS: two routers, certificates made here."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest
import zenoh

from common.config import TlsConfig, zenoh_config
from common.transport import Latest
from tests.conftest import free_port

pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="needs openssl")


def make_certs(d: Path) -> TlsConfig:
    def ssl(*args: str) -> None:
        subprocess.run(["openssl", *args], cwd=d, check=True, capture_output=True)

    ssl(
        "req",
        "-x509",
        "-newkey",
        "rsa:2048",
        "-nodes",
        "-keyout",
        "ca.key",
        "-out",
        "ca.pem",
        "-days",
        "1",
        "-subj",
        "/CN=phenorover-test-ca",
    )
    ssl(
        "req",
        "-newkey",
        "rsa:2048",
        "-nodes",
        "-keyout",
        "node.key",
        "-out",
        "node.csr",
        "-subj",
        "/CN=localhost",
    )
    (d / "ext.cnf").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\n")
    ssl(
        "x509",
        "-req",
        "-in",
        "node.csr",
        "-CA",
        "ca.pem",
        "-CAkey",
        "ca.key",
        "-CAcreateserial",
        "-out",
        "node.pem",
        "-days",
        "1",
        "-extfile",
        "ext.cnf",
    )
    return TlsConfig(
        root_ca=str(d / "ca.pem"),
        certificate=str(d / "node.pem"),
        private_key=str(d / "node.key"),
        mutual=True,
    )


def test_routers_link_over_mutual_tls_and_refuse_strangers(tmp_path: Path) -> None:
    tls = make_certs(tmp_path)
    robot_ep = f"tls/localhost:{free_port()}"
    laptop_ep = f"tcp/127.0.0.1:{free_port()}"
    robot = zenoh.open(zenoh_config("router", [robot_ep], [], tls))
    laptop = zenoh.open(zenoh_config("router", [laptop_ep], [robot_ep], tls))
    on_robot = zenoh.open(zenoh_config("client", [], [robot_ep], tls))
    on_laptop = zenoh.open(zenoh_config("client", [], [laptop_ep]))
    try:
        got: Latest[bytes] = Latest()
        on_laptop.declare_subscriber("phenorover/test/tls", lambda s: got.put(s.payload.to_bytes()))
        for _ in range(50):
            on_robot.put("phenorover/test/tls", b"over tls")
            if got.wait_for(lambda v: True, timeout=0.1):
                break
        assert got.get() == b"over tls"
        stranger = TlsConfig(root_ca=tls.root_ca)  # trusts the CA, has no certificate
        with pytest.raises(zenoh.ZError):
            zenoh.open(zenoh_config("client", [], [robot_ep], stranger, client_timeout_s=2.0))
    finally:
        for s in (on_laptop, on_robot, laptop, robot):
            s.close()
