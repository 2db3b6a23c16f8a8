"""Process helpers a service may need: a free port for a private deployment, and
children that die with their parent or are stopped."""

from __future__ import annotations

import ctypes
import re
import signal
import socket
import subprocess

_PR_SET_PDEATHSIG = 1


def free_loopback_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now (for a private
    deployment beside a running one: experiments, tests)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def die_with_parent() -> None:
    """In a child process: get SIGTERM when the parent dies, so a SIGKILLed parent
    leaves no orphans (Linux prctl PR_SET_PDEATHSIG)."""
    libc = ctypes.CDLL("libc.so.6", use_errno=True)
    libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)


def stop_process(proc: subprocess.Popen[bytes], grace_s: float) -> None:
    """SIGTERM to a child still running, and SIGKILL when it has not exited within
    ``grace_s`` seconds; returns once it has."""
    if proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(timeout=grace_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def strip_ansi(line: str) -> str:
    """A child process's output line without its terminal colours (zenohd's and
    rerun's logs colour their levels)."""
    return _ANSI.sub("", line)
