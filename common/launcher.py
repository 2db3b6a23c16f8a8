"""``phenorover up``: run the services a manifest lists for this machine.

The launcher hosts this machine's Zenoh router, starts each service as its own
process (``python -m services.<name> --manifest M``), prefixes their output with the
service name, restarts a service that dies (exponential backoff, logged), and on
stop sends SIGTERM to all and SIGKILL to whatever is left after ``grace_s``.
"""

from __future__ import annotations

import ctypes
import dataclasses
import importlib
import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import IO, Any

import msgspec
import zenoh

from common.config import ConfigError, Manifest, decode_section, load_manifest, zenoh_config
from services import SERVICES

log = logging.getLogger("phenorover.up")

_PR_SET_PDEATHSIG = 1


def free_loopback_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now (for a private
    deployment beside a running one: experiments, tests)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def config_type(service: str, where: str) -> type[msgspec.Struct]:
    spec = SERVICES.get(service)
    if spec is None:
        known = ", ".join(sorted(SERVICES))
        raise ConfigError(f"{where}: unknown service {service!r} (known: {known})")
    module, _, attr = spec.partition(":")
    t: type[msgspec.Struct] = getattr(importlib.import_module(module), attr)
    return t


def validate(path: Path) -> Manifest:
    """Load a manifest and check every service section against its config type."""
    manifest = load_manifest(path)
    for name, section in manifest.services.items():
        where = f"{path}: [services.{name}]"
        decode_section(section, config_type(name, where), where)
    return manifest


def die_with_parent() -> None:
    """In a child process: get SIGTERM when the parent dies, so a SIGKILLed parent
    leaves no orphans (Linux prctl PR_SET_PDEATHSIG)."""
    libc = ctypes.CDLL("libc.so.6", use_errno=True)
    libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)


@dataclasses.dataclass
class Child:
    name: str
    proc: subprocess.Popen[bytes] | None = None
    restarts: int = 0
    started_at: float = 0.0
    next_start: float = 0.0
    backoff: float = 0.5


class Launcher:
    def __init__(
        self,
        manifest_path: Path,
        out: IO[str] | None = None,
        extra_args: dict[str, list[str]] | None = None,
        grace_s: float = 4.0,
    ) -> None:
        self.path = manifest_path
        self.manifest = validate(manifest_path)
        self.out = out or sys.stdout
        self.extra_args = extra_args or {}
        self.grace_s = grace_s
        self.children = {name: Child(name) for name in self.manifest.services}
        self._stopping = threading.Event()
        self._out_lock = threading.Lock()
        self._router: zenoh.Session | None = None
        self._monitor: threading.Thread | None = None

    def _print(self, name: str, line: str) -> None:
        with self._out_lock:
            self.out.write(f"{name:>8} | {line}\n")
            self.out.flush()

    def _spawn(self, child: Child) -> None:
        cmd = [sys.executable, "-m", f"services.{child.name}", "--manifest", str(self.path)]
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
        zenoh.init_log_from_env_or("error")
        try:
            self._router = zenoh.open(zenoh_config("router", zs.listen, zs.connect, zs.tls))
        except zenoh.ZError as exc:
            raise ConfigError(
                f"{self.path}: cannot open the router on {zs.listen}: {exc}"
            ) from None
        log.info("router on %s, connecting to %s", zs.listen, zs.connect or "nobody")
        for child in self.children.values():
            self._spawn(child)
        self._monitor = threading.Thread(target=self._watch, daemon=True)
        self._monitor.start()

    def _watch(self) -> None:
        while not self._stopping.wait(0.1):
            now = time.monotonic()
            for child in self.children.values():
                proc = child.proc
                if proc is not None and proc.poll() is not None:
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
                elif proc is None and now >= child.next_start:
                    child.restarts += 1
                    log.warning("restarting service %s (restart %d)", child.name, child.restarts)
                    self._spawn(child)

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
        if self._router is not None:
            self._router.close()
            self._router = None
        log.info("all services stopped")

    def __enter__(self) -> Launcher:
        self.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()


def up(manifest_path: Path) -> int:
    """Run until SIGINT/SIGTERM; 0 on a clean stop, 2 on a bad manifest."""
    try:
        launcher = Launcher(manifest_path)
    except ConfigError as exc:
        print(f"phenorover up: {exc}", file=sys.stderr)
        return 2
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
