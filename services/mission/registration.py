"""Registration at the end of a mission: ``python -m services.register RUN_DIR`` as a
child process of the mission service, and :func:`wait_registration` for a command
that waits for it.

Why a child process of the mission service: the mission service is the one part of
a deployment that knows when a survey is done, whatever started it (``phenorover
sim``, ``phenorover mission start`` from a laptop, a resume after a restart), and it
runs where the mission log is written. Registration is heavy (tens of seconds of
both cores), so it runs only once the robot is parked at the Origin, at low CPU
priority (``nice 10``), and in its own process: a crash or a kill of the
registration cannot take the mission service down, and it opens the mission log
read-only, so it can never lose or corrupt it. The child is started by module name:
the mission service imports nothing of the register service. It is given the
deployment's manifest, so it reads its options from ``[services.register]`` as
``phenorover register --manifest`` does. Its output goes to ``RUN_DIR/register.log``;
its start and end are mission events, and while it runs the mission state's
``detail`` is :data:`~common.messages.mission.REGISTERING`. Stopping the mission
service stops the registration (its outputs are written atomically, so none is left
half written); ``phenorover register RUN_DIR`` redoes it at any time, on any machine
holding the run folder and the scans.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import threading
from collections.abc import Callable
from pathlib import Path

from common import keys
from common.messages.mission import REGISTERING, MissionPhase, MissionState
from common.transport import Bus

# the register service's module, run as a program (never imported here)
REGISTER_MODULE = "services.register"
# (level, text): a mission event
Report = Callable[[str, str], None]


class RegistrationJob:
    """One registration of ``run_dir`` in a child process; ``report`` is called from a
    watcher thread when it ends. ``manifest``: the deployment's manifest, passed on
    (``--manifest``) for its ``[services.register]`` options; None: the defaults."""

    def __init__(self, run_dir: Path, report: Report, manifest: Path | None = None) -> None:
        self.run_dir = run_dir
        self.report = report
        self.manifest = manifest
        self.log_path = run_dir / "register.log"
        self._proc: subprocess.Popen[bytes] | None = None
        self._stopping = threading.Event()

    def command(self) -> list[str]:
        """The child's command line."""
        cmd = [sys.executable, "-m", REGISTER_MODULE, str(self.run_dir)]
        if self.manifest is not None:
            cmd += ["--manifest", str(self.manifest)]
        if shutil.which("nice"):
            cmd = ["nice", "-n", "10", *cmd]
        return cmd

    def start(self) -> None:
        """Start the child; raises OSError when it cannot be started."""
        with open(self.log_path, "wb") as out:
            self._proc = subprocess.Popen(
                self.command(), stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL
            )
        threading.Thread(target=self._watch, daemon=True, name="register-watch").start()

    @property
    def running(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def _watch(self) -> None:
        assert self._proc is not None
        rc = self._proc.wait()
        if self._stopping.is_set():
            return
        if rc == 0:
            self.report("info", f"registration done: {self.run_dir / 'report.md'}")
        else:
            self.report("error", f"registration failed (exit {rc}): {self._last_line()}")

    def _last_line(self) -> str:
        try:
            lines = self.log_path.read_text(errors="replace").strip().splitlines()
        except OSError:
            return f"see {self.log_path}"
        return lines[-1] if lines else f"no output in {self.log_path}"

    def stop(self, timeout: float = 2.0) -> None:
        """Terminate a running registration (SIGTERM, then SIGKILL after ``timeout``)."""
        self._stopping.set()
        p = self._proc
        if p is None or p.poll() is not None:
            return
        p.send_signal(signal.SIGTERM)
        try:
            p.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.kill(p.pid, signal.SIGKILL)
            p.wait()


def wait_registration(bus: Bus, final: MissionState, timeout: float) -> MissionState:
    """After a mission ended in ``final``: the mission state once the registration the
    mission service started for it has ended (``final`` itself when none runs).
    Prints progress to stdout and a timeout to stderr (it serves commands)."""
    if final.phase != MissionPhase.DONE or final.detail != REGISTERING:
        return final
    print(f"{final.mission}: registering the scans ...", flush=True)
    state = bus.latest(keys.MISSION_STATE)
    end = state.wait_for(
        lambda s: s.mission == final.mission and s.detail != REGISTERING, timeout=timeout
    )
    if end is None:
        print(f"registration not finished after {timeout:.0f} s", file=sys.stderr, flush=True)
        return final
    return end
