"""``phenorover up`` and ``phenorover status`` as a user runs them."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import zenoh

from common.cli import wait_alive
from common.config import zenoh_config
from tests.conftest import REPO, Procs, free_port, pid_alive


def write_manifest(tmp: Path, port: int, extra: str = "") -> Path:
    m = tmp / "test.toml"
    m.write_text(
        f"""machine = "testbox"
clock = "sim"
[zenoh]
listen = ["tcp/127.0.0.1:{port}"]
[services.sim]
real_time_factor = 5.0
[services.gnss]
{extra}"""
    )
    return m


def test_up_restarts_a_killed_service_and_stops_cleanly(procs: Procs, tmp_path: Path) -> None:
    port = free_port()
    manifest = write_manifest(tmp_path, port)
    log = tmp_path / "up.log"
    up = procs.start("-m", "common.cli", "up", str(manifest), log=log)
    session = zenoh.open(zenoh_config("client", [], [f"tcp/127.0.0.1:{port}"]))
    try:
        seen = wait_alive(session, {"sim", "gnss"}, timeout=30)
        assert {a.service for a in seen} >= {"sim", "gnss"}
        assert all(a.machine == "testbox" for a in seen)
        gnss_pid = next(a.pid for a in seen if a.service == "gnss")
        all_pids = {a.pid for a in seen}
        os.kill(gnss_pid, signal.SIGKILL)
        deadline = time.monotonic() + 30
        new_pid = None
        while new_pid is None:
            assert time.monotonic() < deadline, "killed service was not restarted"
            for a in wait_alive(session, {"gnss"}, timeout=2):
                if a.service == "gnss" and a.pid != gnss_pid:
                    new_pid = a.pid
        all_pids.add(new_pid)
        status = subprocess.run(
            [sys.executable, "-m", "common.cli", "status", "--connect", f"tcp/127.0.0.1:{port}"],
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
    t0 = time.monotonic()
    up.send_signal(signal.SIGTERM)
    assert up.wait(timeout=10) == 0
    assert time.monotonic() - t0 < 5.0
    text = log.read_text()
    assert "service gnss exited with code -9; restarting" in text
    assert not [p for p in all_pids if pid_alive(p)], "a service outlived the launcher"


def test_manifest_typo_is_one_clear_error_before_anything_starts(tmp_path: Path) -> None:
    manifest = write_manifest(tmp_path, free_port(), extra="bakend = 'sim'\n")
    r = subprocess.run(
        [sys.executable, "-m", "common.cli", "up", str(manifest)],
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
        [sys.executable, "-m", "common.cli", "up", str(manifest)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert r.returncode == 2
    assert "unknown service 'gnsss'" in r.stderr and len(r.stderr.strip().splitlines()) == 1
