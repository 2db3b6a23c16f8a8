"""``phenorover up``, ``up --check`` and ``status`` as a user runs them, and the
commands that cannot reach their deployment."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import zenoh

from common.client import wait_alive
from common.config import zenoh_config
from tests.conftest import REPO, Procs, free_port, pid_alive


def write_manifest(tmp: Path, port: int, extra: str = "", field: str = "engr") -> Path:
    m = tmp / "test.toml"
    m.write_text(
        f"""machine = "testbox"
clock = "sim"
field = "{field}"
[zenoh]
listen = ["tcp/127.0.0.1:{port}"]
[services.sim]
real_time_factor = 5.0
[services.gnss]
backend = "sim"
{extra}"""
    )
    return m


def replaced(session: zenoh.Session, service: str, pid: int, timeout: float = 30) -> int:
    """The pid of the process alive as ``service`` in place of ``pid``."""
    deadline = time.monotonic() + timeout
    while True:
        assert time.monotonic() < deadline, f"{service} (pid {pid}) was not replaced"
        for a in wait_alive(session, {service}, timeout=2).seen:
            if a.service == service and a.pid != pid:
                return a.pid


def test_up_restarts_a_killed_service_and_stops_cleanly(procs: Procs, tmp_path: Path) -> None:
    port = free_port()
    manifest = write_manifest(tmp_path, port)
    log = tmp_path / "up.log"
    up = procs.start("-m", "phenorover", "up", str(manifest), log=log)
    session = zenoh.open(zenoh_config("client", [], [f"tcp/127.0.0.1:{port}"]))
    try:
        seen = wait_alive(session, {"sim", "gnss"}, timeout=30).seen
        assert {a.service for a in seen} >= {"sim", "gnss"}
        assert all(a.machine == "testbox" for a in seen)
        gnss_pid = next(a.pid for a in seen if a.service == "gnss")
        all_pids = {a.pid for a in seen}
        os.kill(gnss_pid, signal.SIGKILL)
        new_pid = replaced(session, "gnss", gnss_pid)
        all_pids.add(new_pid)
        status = subprocess.run(
            [sys.executable, "-m", "phenorover", "status", "--connect", f"tcp/127.0.0.1:{port}"],
            cwd=REPO,
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert status.returncode == 0, status.stderr
        assert (
            "gnss" in status.stdout and "testbox" in status.stdout and str(new_pid) in status.stdout
        )
    finally:
        session.close()
    up.send_signal(signal.SIGTERM)
    assert up.wait(timeout=10) == 0
    text = log.read_text()
    # every service stopped on its SIGTERM, none waited out and killed
    assert "did not stop in" not in text and "all services stopped" in text
    assert "service gnss exited with code -9; restarting" in text
    assert not [p for p in all_pids if pid_alive(p)], "a service outlived the launcher"


def test_manifest_typo_is_one_clear_error_before_anything_starts(tmp_path: Path) -> None:
    manifest = write_manifest(tmp_path, free_port(), extra="bakend = 'sim'\n")
    r = subprocess.run(
        [sys.executable, "-m", "phenorover", "up", str(manifest)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert "test.toml" in lines[0] and "[services.gnss]" in lines[0] and "bakend" in lines[0]


def test_unknown_service_in_manifest(tmp_path: Path) -> None:
    manifest = write_manifest(tmp_path, free_port(), extra="[services.gnsss]\n")
    r = subprocess.run(
        [sys.executable, "-m", "phenorover", "up", str(manifest)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert r.returncode == 2
    assert "unknown service 'gnsss'" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def run_cli(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "phenorover", *args],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def test_a_missing_field_is_refused_before_anything_starts(tmp_path: Path) -> None:
    port = free_port()
    manifest = write_manifest(tmp_path, port, field=str(tmp_path / "nowhere.toml"))
    r = run_cli("up", str(manifest))
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr  # no service got to start and fail
    assert "test.toml: field:" in lines[0] and "nowhere.toml" in lines[0]
    assert r.stdout == ""


def test_a_malformed_field_and_no_field_are_refused(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("rows = 'many'\n")
    for field, says in ((str(bad), "bad.toml"), ("", "need the surveyed field")):
        r = run_cli("up", str(write_manifest(tmp_path, free_port(), field=field)))
        assert r.returncode == 2
        assert len(r.stderr.strip().splitlines()) == 1 and says in r.stderr, r.stderr


def test_a_device_section_must_name_its_backend(tmp_path: Path) -> None:
    manifest = write_manifest(tmp_path, free_port(), extra="[services.base]\n")
    r = run_cli("up", "--check", str(manifest))
    assert r.returncode == 2
    assert "[services.base]" in r.stderr and "`backend`" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_up_check_names_what_it_would_open_and_what_is_missing(tmp_path: Path) -> None:
    card = tmp_path / "card"
    card.mkdir()
    missing = "/dev/ttyPHENOROVER-TEST"
    manifest = write_manifest(
        tmp_path,
        free_port(),
        extra=f"""[services.scanner]
backend = "can"
interface = "socketcan"
channel = "canPHENO9"
storage_dir = "{card}"
""",
    )
    text = manifest.read_text().replace(
        '[services.gnss]\nbackend = "sim"',
        f'[services.gnss]\nbackend = "nmea-serial"\nantennas = [{{id = 1, port = "{missing}"}}]',
    )
    manifest.write_text(text)
    r = run_cli("up", "--check", str(manifest))
    assert r.returncode == 2, r.stdout + r.stderr
    assert f"antenna 1: serial {missing} at 115200 baud" in r.stdout
    assert "CAN socketcan canPHENO9" in r.stdout and f"scan files in {card}" in r.stdout
    problems = r.stderr.strip().splitlines()
    assert len(problems) == 2, r.stderr
    assert f"gnss: {missing}: no such device" in problems[0]
    assert "scanner: canPHENO9: no such CAN interface" in problems[1]
    ok = run_cli("up", "--check", str(REPO / "deploy" / "sim.toml"))
    assert ok.returncode == 0 and "ready to start" in ok.stdout, ok.stderr


def test_commands_that_cannot_reach_their_deployment_say_where_in_one_line() -> None:
    ep = f"tcp/127.0.0.1:{free_port()}"  # nothing listens there
    commands = {
        "status": ["status", "--connect", ep],
        "mission status": ["mission", "status", "--connect", ep],
        "mission start": ["mission", "start", "--connect", ep],
        "plan --remote": ["plan", "engr", "--remote", "--connect", ep],
    }
    runs = {
        name: subprocess.Popen(
            [sys.executable, "-m", "phenorover", *args],
            cwd=REPO,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for name, args in commands.items()
    }
    for name, p in runs.items():
        out, err = p.communicate(timeout=60)
        assert p.returncode == 2, (name, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and ep in lines[0] and "no router" in lines[0], (name, err)
        assert "Traceback" not in err and out == "", (name, out)


def test_a_command_whose_service_is_not_alive_says_so_at_once(router_endpoint: str) -> None:
    # the router answers, but nothing behind it serves missions or plans (the robot off)
    for args, service in (
        (["mission", "status"], "mission"),
        (["plan", "engr", "--remote"], "planner"),
    ):
        r = run_cli(*args, "--connect", router_endpoint, timeout=30)
        assert r.returncode == 2, r.stderr
        lines = r.stderr.strip().splitlines()
        assert (
            len(lines) == 1 and f"no {service} service alive behind {router_endpoint}" in lines[0]
        )


def test_up_kills_and_restarts_a_hung_service(procs: Procs, tmp_path: Path) -> None:
    """A service stopped by SIGSTOP keeps its process (and for a while its liveliness
    token): its silent heartbeat gives it away, and it is replaced as a dead one is."""
    port = free_port()
    manifest = write_manifest(tmp_path, port)
    manifest.write_text("hung_after_s = 3.0\n" + manifest.read_text())
    log = tmp_path / "up.log"
    procs.start("-m", "phenorover", "up", str(manifest), log=log)
    session = zenoh.open(zenoh_config("client", [], [f"tcp/127.0.0.1:{port}"]))
    try:
        seen = wait_alive(session, {"gnss"}, timeout=30).seen
        hung = next(a.pid for a in seen if a.service == "gnss")
        # judged only once heard: a heartbeat of it on the bus has reached the router
        beat = threading.Event()
        sub = session.declare_subscriber("phenorover/health/gnss", lambda _s: beat.set())
        assert beat.wait(10), "no heartbeat from gnss"
        sub.undeclare()
        os.kill(hung, signal.SIGSTOP)
        replaced(session, "gnss", hung)
        assert not pid_alive(hung), "the hung process was left behind"
        assert f"service gnss (pid {hung}) has not been heard for" in log.read_text()
    finally:
        session.close()
