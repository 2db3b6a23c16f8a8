"""``phenorover.certs`` and ``phenorover certs``: a CA and machine certificates that round
trip, private keys, no silent overwrite, one-line errors."""

from __future__ import annotations

import ipaddress
import stat
import subprocess
import sys
from pathlib import Path

import pytest
from cryptography import x509

from phenorover.certs import (
    CertError,
    common_name,
    init_ca,
    issue_files,
    read_cert,
    read_key,
    tls_problems,
)
from tests.conftest import REPO


def mode(p: Path) -> int:
    return stat.S_IMODE(p.stat().st_mode)


def test_ca_and_machine_certificates_round_trip(tmp_path: Path) -> None:
    assert init_ca(tmp_path) == [tmp_path / "ca.pem", tmp_path / "ca.key"]
    written = issue_files("robot", tmp_path, ["rover.local", "127.0.0.1"])
    assert written == [tmp_path / "robot.pem", tmp_path / "robot.key"]
    ca, cert = read_cert(tmp_path / "ca.pem"), read_cert(tmp_path / "robot.pem")
    cert.verify_directly_issued_by(ca)
    assert common_name(cert) == "robot"
    san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert san.get_values_for_type(x509.DNSName) == ["robot", "rover.local"]
    assert san.get_values_for_type(x509.IPAddress) == [ipaddress.ip_address("127.0.0.1")]
    assert read_key(tmp_path / "robot.key").public_key() == cert.public_key()
    assert mode(tmp_path / "ca.key") == mode(tmp_path / "robot.key") == 0o600
    assert (
        tls_problems(tmp_path / "ca.pem", tmp_path / "robot.pem", tmp_path / "robot.key", "robot")
        == []
    )


def test_nothing_is_overwritten_without_force(tmp_path: Path) -> None:
    init_ca(tmp_path)
    issue_files("jetson", tmp_path)
    before = (tmp_path / "jetson.pem").read_bytes()
    with pytest.raises(CertError, match=r"jetson\.pem exists \(use --force"):
        issue_files("jetson", tmp_path)
    with pytest.raises(CertError, match=r"ca\.pem exists"):
        init_ca(tmp_path)
    assert (tmp_path / "jetson.pem").read_bytes() == before
    issue_files("jetson", tmp_path, force=True)
    assert (tmp_path / "jetson.pem").read_bytes() != before
    assert mode(tmp_path / "jetson.key") == 0o600


def test_bad_names_and_a_missing_ca_are_one_line(tmp_path: Path) -> None:
    with pytest.raises(CertError, match="run `phenorover certs init` first"):
        issue_files("robot", tmp_path)
    init_ca(tmp_path)
    for bad in ("Robot", "base_station", "", "-x"):
        with pytest.raises(CertError, match="machine name"):
            issue_files(bad, tmp_path)


def test_tls_problems_name_a_wrong_machine_a_foreign_ca_and_an_open_key(tmp_path: Path) -> None:
    ours, theirs = tmp_path / "ours", tmp_path / "theirs"
    init_ca(ours)
    init_ca(theirs)
    issue_files("robot", ours)
    issue_files("robot", theirs)
    key = ours / "robot.key"
    key.chmod(0o644)
    problems = tls_problems(ours / "ca.pem", theirs / "robot.pem", key, "jetson")
    assert any("not signed by" in p for p in problems)
    assert any("common name 'robot', not the machine 'jetson'" in p for p in problems)
    assert any("not the key of" in p for p in problems)
    assert any("readable by others" in p for p in problems)
    assert tls_problems(tmp_path / "no.pem", None, None, "robot") == [
        f"root_ca {tmp_path / 'no.pem'}: cannot read: No such file or directory"
    ]


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "phenorover", "certs", *args],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_the_certs_command(tmp_path: Path) -> None:
    d = str(tmp_path / "certs")
    assert cli("init", "--dir", d).returncode == 0
    r = cli("issue", "basestation", "--dir", d, "--loopback", "--host", "laptop.local")
    assert r.returncode == 0 and r.stdout.count("wrote ") == 2, r.stderr
    san = read_cert(Path(d) / "basestation.pem").extensions.get_extension_for_class(
        x509.SubjectAlternativeName
    )
    assert "localhost" in san.value.get_values_for_type(x509.DNSName)
    again = cli("issue", "basestation", "--dir", d)
    assert again.returncode == 2 and len(again.stderr.strip().splitlines()) == 1
    assert "--force" in again.stderr and "Traceback" not in again.stderr
