"""Registration and traits at the end of a mission: ``python -m services.register
RUN_DIR`` as a child process of the mission service, then ``python -m services.traits
RUN_DIR`` (when registration succeeded and ``traits_on_done`` asks for it), and
:func:`wait_registration` for a command that waits for both.

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
``detail`` is :data:`~common.messages.mission.REGISTERING` (then
:data:`~common.messages.mission.COMPUTING_TRAITS`, output in ``RUN_DIR/traits.log``).
The traits are as light a step and run the same way. Stopping the mission
service stops the registration (its outputs are written atomically, so none is left
half written); ``phenorover register RUN_DIR`` redoes it at any time, on any machine
holding the run folder and the scans.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import threading
from collections.abc import Callable
from pathlib import Path

from common import keys
from common.messages.mission import (
    COMPUTING_TRAITS,
    POST_PROCESSING,
    REGISTERING,
    MissionPhase,
    MissionState,
)
from common.process import stop_process
from common.transport import Bus

# the modules run as programs, in this order (never imported here)
REGISTER_MODULE = "services.register"
TRAITS_MODULE = "services.traits"
# (level, text): a mission event
Report = Callable[[str, str], None]
# how the event of a registration that succeeded begins
REGISTERED = "registration done"


class RegistrationJob:
    """The registration of ``run_dir`` in a child process, then (``traits``: when it
    succeeded) its per-plot traits in another; ``report`` is called from a watcher
    thread as each step ends, and with :data:`COMPUTING_TRAITS` when the traits start.
    ``manifest``: the deployment's manifest, passed on (``--manifest``) for the
    steps' ``[services.register]`` and ``[services.traits]`` options; None: defaults."""

    def __init__(
        self,
        run_dir: Path,
        report: Report,
        manifest: Path | None = None,
        traits: bool = False,
        modules: tuple[str, str] = (REGISTER_MODULE, TRAITS_MODULE),
    ) -> None:
        self.run_dir = run_dir
        self.modules = modules  # (registration, traits), run with ``python -m``
        self.report = report
        self.manifest = manifest
        self.traits = traits
        self.log_path = run_dir / "register.log"
        self.traits_log = run_dir / "traits.log"
        self._proc: subprocess.Popen[bytes] | None = None
        self._stopping = threading.Event()
        self._lock = threading.Lock()

    def command(self, module: str = REGISTER_MODULE) -> list[str]:
        """A step's command line."""
        cmd = [sys.executable, "-m", module, str(self.run_dir)]
        if self.manifest is not None:
            cmd += ["--manifest", str(self.manifest)]
        if shutil.which("nice"):
            cmd = ["nice", "-n", "10", *cmd]
        return cmd

    def start(self) -> None:
        """Start the registration; raises OSError when it cannot be started."""
        self._spawn(self.modules[0], self.log_path)
        threading.Thread(target=self._watch, daemon=True, name="register-watch").start()

    def _spawn(self, module: str, log_path: Path) -> None:
        with self._lock:
            if self._stopping.is_set():
                return
            with open(log_path, "wb") as out:
                self._proc = subprocess.Popen(
                    self.command(module),
                    stdout=out,
                    stderr=subprocess.STDOUT,
                    stdin=subprocess.DEVNULL,
                )

    @property
    def running(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def _wait(self) -> int | None:
        """The current step's exit status; None when the job was stopped."""
        assert self._proc is not None
        rc = self._proc.wait()
        return None if self._stopping.is_set() else rc

    def _watch(self) -> None:
        rc = self._wait()
        if rc is None:
            return
        if rc != 0:
            self.report("error", f"registration failed (exit {rc}): {_last_line(self.log_path)}")
            return
        self.report("info", f"{REGISTERED}: {self.run_dir / 'report.md'}")
        if not self.traits:
            return
        try:
            self._spawn(self.modules[1], self.traits_log)
        except OSError as exc:
            self.report("error", f"traits not started: {exc}")
            return
        self.report("info", COMPUTING_TRAITS)
        rc = self._wait()
        if rc is None:
            return
        if rc == 0:
            self.report("info", f"traits done: {self.run_dir / 'traits.csv'}")
        else:
            self.report("error", f"traits failed (exit {rc}): {_last_line(self.traits_log)}")

    def stop(self, timeout: float = 2.0) -> None:
        """Terminate a running step (SIGTERM, then SIGKILL after ``timeout``); no
        further step starts."""
        with self._lock:
            self._stopping.set()
        if self._proc is not None:
            stop_process(self._proc, timeout)


def start_registration(
    run_dir: Path,
    manifest: Path | None,
    traits: bool,
    detail: Callable[[str], None],
    event: Report,
) -> RegistrationJob | None:
    """Start the registration (and then the traits) of ``run_dir``; every outcome is an
    ``event`` and the mission state's ``detail``, except a registration the traits
    follow: the detail stays :data:`REGISTERING` until they start, so nobody waiting
    on it sees the gap between the two. None (and an error event) when it cannot
    start."""

    def report(level: str, text: str) -> None:
        if not (traits and text.startswith(REGISTERED)):
            detail(text)
        event(level, text)

    job = RegistrationJob(run_dir, report, manifest, traits)
    try:
        job.start()
    except OSError as exc:
        event("error", f"registration not started: {exc}")
        return None
    detail(REGISTERING)
    event("info", f"{REGISTERING} the scans: log in {job.log_path}")
    return job


def _last_line(path: Path) -> str:
    try:
        lines = path.read_text(errors="replace").strip().splitlines()
    except OSError:
        return f"see {path}"
    return lines[-1] if lines else f"no output in {path}"


def wait_registration(bus: Bus, final: MissionState, timeout: float) -> MissionState:
    """After a mission ended in ``final``: the mission state once the registration the
    mission service started for it has ended (``final`` itself when none runs).
    Prints progress to stdout and a timeout to stderr (it serves commands)."""
    if final.phase != MissionPhase.DONE or final.detail not in POST_PROCESSING:
        return final
    print(f"{final.mission}: registering the scans ...", flush=True)
    state = bus.latest(keys.MISSION_STATE)
    end = state.wait_for(
        lambda s: s.mission == final.mission and s.detail not in POST_PROCESSING,
        timeout=timeout,
    )
    if end is None:
        print(
            f"registration and traits not finished after {timeout:.0f} s",
            file=sys.stderr,
            flush=True,
        )
        return final
    return end
