"""``phenorover up``: run the services a manifest lists for this machine.

The launcher hosts this machine's Zenoh router, starts each service as its own
process (``python -m services.<name> --manifest M``, or the module
``services.MODULES`` names), prefixes their output with the
service name, restarts a service that dies (exponential backoff, logged), kills and
restarts one that hangs (its heartbeat silent for the manifest's ``hung_after_s``,
:mod:`phenorover.watchdog`), and on stop sends SIGTERM to all and SIGKILL to
whatever is left after ``grace_s``.

Everything is checked before anything starts (:mod:`phenorover.preflight`):
a manifest that names a missing field or mistyped key is one error line, never a
service restarted in a loop. With ``[zenoh.access]`` the router enforces access control
(:mod:`common.acl`) and the denials it logs (:mod:`common.acl_log`) come out as
``phenorover.acl`` warnings.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import IO, Any

import zenoh

from common import keys
from common.acl_log import DenialLog
from common.config import ConfigError, load_manifest
from common.messages.sim import SimRun
from common.process import die_with_parent
from common.transport import Bus
from phenorover.cpu import cpu_seconds
from phenorover.preflight import config_type as config_type  # re-exported: tests, tools
from phenorover.preflight import preflight
from phenorover.router import ACL_LOG_FILTER, StdoutFilter, router_config
from phenorover.watchdog import HeartbeatWatch
from services import SERVICES, module_of

log = logging.getLogger("phenorover.up")
acl_log = logging.getLogger("phenorover.acl")


@dataclasses.dataclass
class Child:
    name: str
    proc: subprocess.Popen[bytes] | None = None
    restarts: int = 0
    started_at: float = 0.0
    next_start: float = 0.0
    backoff: float = 0.5
    cpu_done: float = 0.0  # CPU seconds of its earlier processes (restarts)
    cpu_last: float = 0.0  # of the current one, as last read


class Launcher:
    def __init__(
        self,
        manifest_path: Path,
        out: IO[str] | None = None,
        extra_args: dict[str, list[str]] | None = None,
        grace_s: float = 4.0,
        field: str | None = None,
    ) -> None:
        """``field``: the field of every service instead of the manifest's (checked as
        such). Raises ConfigError when :func:`preflight` finds the deployment wrong;
        ``notes`` are its start-up lines."""
        self.path = manifest_path
        self.manifest, self.notes = preflight(manifest_path, field)
        self.out = out or sys.stdout
        self.extra_args = extra_args or {}
        if field is not None:
            self.extra_args = {n: ["--field", field, *self.extra_args.get(n, [])] for n in SERVICES}
        self.grace_s = grace_s
        # jobs (``services.JOBS``, e.g. register) are configured here but run on demand
        self.children = {name: Child(name) for name in self.manifest.services if name in SERVICES}
        self._stopping = threading.Event()
        self._out_lock = threading.Lock()
        self._cpu_lock = threading.Lock()
        self._router: zenoh.Session | None = None
        self._monitor: threading.Thread | None = None
        self._denials: StdoutFilter | None = None
        self.heartbeats = HeartbeatWatch(self.manifest.machine, self.manifest.hung_after_s)

    def _print(self, name: str, line: str) -> None:
        # a robot's services by its namespace too: several robots may share a terminal
        label = keys.participant(name, self.manifest.namespace)
        with self._out_lock:
            self.out.write(f"{label:>8} | {line}\n")
            self.out.flush()

    def _spawn(self, child: Child) -> None:
        cmd = [sys.executable, "-m", module_of(child.name), "--manifest", str(self.path)]
        cmd += self.extra_args.get(child.name, [])
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        proc = subprocess.Popen(
            cmd,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            env=env,
            preexec_fn=die_with_parent,
        )
        child.proc = proc
        child.started_at = time.monotonic()
        threading.Thread(target=self._pump, args=(child.name, proc), daemon=True).start()

    def _pump(self, name: str, proc: subprocess.Popen[bytes]) -> None:
        assert proc.stdout is not None
        for raw in proc.stdout:
            self._print(name, raw.decode(errors="replace").rstrip())

    def start(self) -> None:
        zs = self.manifest.zenoh
        if zs.access is not None:
            self._denials = StdoutFilter(DenialLog(acl_log.warning))
            zenoh.init_log_from_env_or(ACL_LOG_FILTER)
        else:
            zenoh.init_log_from_env_or("error")
        try:
            self._router = zenoh.open(router_config(self.manifest))
        except zenoh.ZError as exc:
            self._close_router()
            msg = " ".join(str(exc).split(" at /")[0].split())
            raise ConfigError(
                f"{self.path}: cannot open the router on {zs.listen}: {msg}"
            ) from None
        log.info(
            "router on %s, connecting to %s%s",
            zs.listen,
            zs.connect or "nobody",
            ", access control on" if zs.access is not None else "",
        )
        for child in self.children.values():
            self._spawn(child)
        self._router.declare_subscriber(
            keys.HEALTH.at(service="*").within(self.manifest.namespace).key,
            lambda sample: self.heartbeats.on_sample(sample.payload.to_bytes(), time.monotonic()),
        )
        self._monitor = threading.Thread(target=self._watch, daemon=True)
        self._monitor.start()

    def _watch(self) -> None:
        while not self._stopping.wait(0.1):
            now = time.monotonic()
            for child in self.children.values():
                proc = child.proc
                self._read_cpu(child)  # before the poll: a zombie still shows its times
                if proc is not None and proc.poll() is None:
                    self._kill_if_hung(child, proc, now)
                if proc is not None and proc.poll() is not None:
                    self.heartbeats.forget(proc.pid)
                    if self._stopping.is_set():
                        return
                    if now - child.started_at > 60.0:
                        child.backoff = 0.5  # it ran a good while: a fresh failure
                    child.next_start = now + child.backoff
                    log.warning(
                        "service %s exited with code %s; restarting in %.1f s",
                        child.name,
                        proc.returncode,
                        child.backoff,
                    )
                    child.backoff = min(child.backoff * 2, 30.0)
                    child.proc = None
                    with self._cpu_lock:
                        child.cpu_done += child.cpu_last
                        child.cpu_last = 0.0
                elif proc is None and now >= child.next_start:
                    child.restarts += 1
                    log.warning("restarting service %s (restart %d)", child.name, child.restarts)
                    self._spawn(child)

    def _kill_if_hung(self, child: Child, proc: subprocess.Popen[bytes], now: float) -> None:
        silent = self.heartbeats.silent_for(proc.pid, now)
        if silent is None:
            return
        log.warning(
            "service %s (pid %d) has not been heard for %.1f s: hung, killing it",
            child.name,
            proc.pid,
            silent,
        )
        proc.kill()  # SIGKILL ends a stopped process too; its exit restarts it below
        with contextlib.suppress(subprocess.TimeoutExpired):  # else reaped next round
            proc.wait(timeout=self.grace_s)

    def _read_cpu(self, child: Child) -> None:
        seconds = cpu_seconds(child.proc.pid) if child.proc is not None else None
        if seconds is not None:
            with self._cpu_lock:
                child.cpu_last = seconds

    def cpu(self) -> dict[str, float]:
        """CPU seconds per service since it was first started, restarts included, as
        the monitor last read them (every 0.1 s; :mod:`phenorover.cpu`; zeros where
        they cannot be read)."""
        with self._cpu_lock:
            return {n: c.cpu_done + c.cpu_last for n, c in self.children.items()}

    def pids(self) -> dict[str, int]:
        return {n: c.proc.pid for n, c in self.children.items() if c.proc is not None}

    def stop(self) -> None:
        self._stopping.set()
        if self._monitor is not None:
            self._monitor.join(timeout=1.0)
        procs = [c.proc for c in self.children.values() if c.proc is not None]
        for p in procs:
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + self.grace_s
        for p in procs:
            try:
                p.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                log.warning("pid %d did not stop in %.0f s: killing it", p.pid, self.grace_s)
                p.kill()
                p.wait()
        self._close_router()
        log.info("all services stopped")

    def _close_router(self) -> None:
        if self._router is not None:
            self._router.close()
            self._router = None
        if self._denials is not None:  # after the router: it logs until it is closed
            self._denials.close()
            self._denials = None

    def __enter__(self) -> Launcher:
        self.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()


def held_world(manifest: Path) -> dict[str, list[str]]:
    """The simulator's extra arguments (a Launcher's ``extra_args``) for a deployment
    in lockstep: its world stands at its start until :func:`release_world`, so that
    whoever starts a survey or an experiment does so first and the same seed gives the
    same run; none for a free-running one. Raises ConfigError for a bad manifest."""
    return {"sim": ["--set", "start_held=true"]} if load_manifest(manifest).lockstep else {}


def release_world(bus: Bus) -> None:
    """Let a world held at its start run (``rpc/sim/run``). Raises RpcError."""
    bus.call(keys.SIM_RUN, SimRun(), timeout=10)


def up(manifest_path: Path) -> int:
    """Run until SIGINT/SIGTERM; 0 on a clean stop, 2 on a bad manifest."""
    try:
        launcher = Launcher(manifest_path)
    except ConfigError as exc:
        print(f"phenorover up: {exc}", file=sys.stderr)
        return 2
    for note in launcher.notes:
        log.warning("%s", note)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    try:
        launcher.start()
    except ConfigError as exc:
        print(f"phenorover up: {exc}", file=sys.stderr)
        return 2
    try:
        stop.wait()
    finally:
        launcher.stop()
    return 0
