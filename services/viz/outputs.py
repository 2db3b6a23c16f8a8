"""Where the dashboard's data goes: rerun recording streams and their sinks.

One *live* stream for the service's lifetime feeds the gRPC server (and the web
viewer), a viewer we connect to, and a fixed ``save`` path. Its recording id is
:func:`live_recording_id` of the service's machine and process, both in its liveliness
token, so another process that sees the token can log into the same served recording
(rerun merges data by application and recording id). A ``save`` path holding
``{mission}`` gets a stream of its own per mission, opened when the mission starts
and closed (footer written) when the next starts or the service stops.

The rerun SDK does its encoding and I/O on its own threads; ``log`` only hands data
over. Every server listens on ``bind``: the gRPC server is the SDK's, the web viewer is
served by rerun's CLI (:class:`WebViewer`). Rerun's analytics live in its viewers, never
in the SDK: the native viewer reads them from ``rerun analytics disable``, the web
viewer from the browser; the CLI serving the web viewer runs with them off.
"""

from __future__ import annotations

import contextlib
import importlib.util
import logging
import os
import socket
import subprocess
import tempfile
import threading
import time
from collections.abc import Iterable
from pathlib import Path
from urllib.parse import quote

import rerun as rr

from common.process import die_with_parent, stop_process, strip_ansi
from services.viz.config import VizConfig
from services.viz.scene import Entry, blueprint

APP_ID = "phenorover"
TIMELINE = "time"
# where this machine's own processes reach a server bound to a wildcard address
LOCAL = {"0.0.0.0": "127.0.0.1", "::": "::1"}

log = logging.getLogger("viz")


def live_recording_id(machine: str, pid: int) -> str:
    """The live stream's recording id of the dashboard running as ``pid`` on ``machine``
    (its liveliness token: ``alive/<machine>/viz/<pid>/...``): a restarted dashboard
    starts a recording of its own, as a new process."""
    return f"{APP_ID}-live-{machine}-{pid}"


def local_url(cfg: VizConfig) -> str:
    """The served gRPC endpoint as a process on this machine reaches it."""
    return f"rerun+http://{LOCAL.get(cfg.bind, cfg.bind)}:{cfg.grpc_port}/proxy"


def set_time(rec: rr.RecordingStream, stamp_ns: int, sim_time: bool) -> None:
    """Put ``rec`` at ``stamp_ns`` on the one timeline: sim time as a duration from the
    world's start, otherwise wall time as a timestamp."""
    if sim_time:
        rec.set_time(TIMELINE, duration=stamp_ns * 1e-9)
    else:
        rec.set_time(TIMELINE, timestamp=stamp_ns * 1e-9)


def port_free(host: str, port: int) -> bool:
    """Whether ``host``:``port`` can be bound now (rerun's server only logs a failure)."""
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError:
            return False
    return True


def rerun_cli() -> Path | None:
    """rerun's command-line program, installed with rerun-sdk (package ``rerun_cli``)."""
    spec = importlib.util.find_spec("rerun_cli")
    if spec is None or spec.origin is None:
        return None
    exe = Path(spec.origin).parent / "rerun"
    return exe if exe.is_file() else None


class WebViewer:
    """Rerun's web viewer (its HTML and Wasm over HTTP) on ``bind``:``port``, linked to
    the gRPC server at ``connect_to``. The SDK's ``rr.serve_web_viewer`` takes no address
    and listens on every interface, so the viewer is served by rerun's own CLI
    (``rerun --serve-web --bind``): a child process that gets SIGTERM when this one
    dies. It starts with a rerun config directory of its own, analytics disabled, so
    serving the viewer sends no usage data, as the SDK sends none; the CLI reads that
    config as it starts, and the directory is removed once the viewer listens.

    Blocks until the viewer accepts connections; raises OSError when it cannot start
    within ``timeout_s`` (the CLI missing, the address taken), naming why."""

    def __init__(self, bind: str, port: int, connect_to: str, timeout_s: float = 10.0) -> None:
        exe = rerun_cli()
        if exe is None:
            raise OSError("rerun's CLI (rerun_cli/rerun, part of rerun-sdk) is not installed")
        if not port_free(bind, port):  # else the readiness check would find the other
            raise OSError(f"{bind}:{port} is in use")
        self._said: list[str] = []
        with tempfile.TemporaryDirectory(prefix="viz-rerun-") as home:
            env = dict(os.environ, XDG_CONFIG_HOME=home, XDG_DATA_HOME=home, RUST_LOG="warn")
            null = subprocess.DEVNULL
            try:
                subprocess.run(
                    [str(exe), "analytics", "disable"],
                    env=env,
                    stdin=null,
                    stdout=null,
                    stderr=null,
                    timeout=timeout_s,
                    check=True,
                )
            except subprocess.SubprocessError as exc:
                raise OSError(f"rerun analytics disable: {exc}") from None
            cmd = [str(exe), "--serve-web", "--bind", bind, "--web-viewer-port", str(port)]
            self.proc = subprocess.Popen(
                [*cmd, connect_to],
                env=env,
                stdin=null,
                stdout=null,
                stderr=subprocess.PIPE,
                preexec_fn=die_with_parent,
            )
            self._pump = threading.Thread(target=self._read, daemon=True, name="viz-web-log")
            self._pump.start()
            ready = self._wait(LOCAL.get(bind, bind), port, timeout_s)
        if not ready:
            self.close()
            said = "; ".join(self._said[-3:]) or f"not listening after {timeout_s:g} s"
            raise OSError(f"rerun --serve-web on {bind}:{port}: {said}")

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for raw in self.proc.stderr:
            line = strip_ansi(raw.decode(errors="replace")).strip()
            if line:
                self._said.append(line)
                log.warning("viz: web viewer: %s", line)

    def _wait(self, host: str, port: int, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                self._pump.join(timeout=1.0)  # what it said before it exited
                return False
            with contextlib.suppress(OSError), socket.create_connection((host, port), 0.2):
                return True
            time.sleep(0.05)  # a poll period: the CLI is starting
        return False

    def close(self) -> None:
        """Stop the viewer's process (it holds no data)."""
        stop_process(self.proc, 1.0)


def save_path(template: str, run_dir: Path, mission: str) -> Path:
    """``template`` expanded; a file that exists already (a restarted dashboard) is
    kept and the new one gets a numbered name next to it."""
    p = Path(template.format(run_dir=run_dir, mission=mission or "no-mission"))
    k = 2
    out = p
    while out.exists():
        out = p.with_name(f"{p.stem}-{k}{p.suffix}")
        k += 1
    return out


class Outputs:
    def __init__(
        self, cfg: VizConfig, run_dir: Path, sim_time: bool, recording_id: str | None = None
    ) -> None:
        """``recording_id``: the live stream's (None: a random one)."""
        self.cfg, self.run_dir, self.sim_time = cfg, run_dir, sim_time
        self.recording_id = recording_id
        self.per_mission = "{mission}" in cfg.save
        self.live: rr.RecordingStream | None = None
        self.mission_stream: rr.RecordingStream | None = None
        self.mission = ""
        self.viewer_url = ""
        self.web: WebViewer | None = None
        self._lock = threading.Lock()

    def start(self) -> None:
        """Open the live stream's sinks. Raises ValueError on a bad ``save`` template."""
        cfg = self.cfg
        sinks: list[rr.GrpcServerSink | rr.GrpcSink | rr.FileSink] = []
        if cfg.serve:
            if port_free(cfg.bind, cfg.grpc_port):
                origins = [f"http://*:{cfg.web_port}"] if cfg.web_port else []
                server = rr.GrpcServerSink(
                    cfg.bind,
                    cfg.grpc_port,
                    server_memory_limit=cfg.server_memory_limit,
                    cors_allow_origin=origins,
                )
                sinks.append(server)
                self._serve_web(server.uri)
            else:
                log.error("viz: cannot serve: %s:%d is in use", cfg.bind, cfg.grpc_port)
        if cfg.connect:
            sinks.append(rr.GrpcSink(cfg.connect))
        if cfg.save and not self.per_mission:
            path = save_path(cfg.save, self.run_dir, "")
            path.parent.mkdir(parents=True, exist_ok=True)
            sinks.append(rr.FileSink(path))
            log.info("viz: saving to %s", path)
        if sinks:
            self.live = rr.RecordingStream(
                APP_ID, recording_id=self.recording_id, send_properties=True
            )
            self.live.set_sinks(*sinks, default_blueprint=blueprint())

    def _serve_web(self, grpc_uri: str) -> None:
        cfg = self.cfg
        host = cfg.advertise or (socket.gethostname() if cfg.bind in LOCAL else cfg.bind)
        url = grpc_uri.replace("127.0.0.1", host).replace("0.0.0.0", host)
        if cfg.web_port:
            try:
                self.web = WebViewer(cfg.bind, cfg.web_port, url)
            except OSError as exc:
                log.error("viz: cannot serve the web viewer: %s", exc)
            else:
                self.viewer_url = f"http://{host}:{cfg.web_port}/?url={quote(url, safe='')}"
                log.info("viz: web viewer at %s", self.viewer_url)
        log.info("viz: live data at %s (rerun --connect %s)", url, url)

    def open_mission(self, mission: str) -> bool:
        """Start ``mission``'s own recording file (when ``save`` names one per mission);
        True when a new stream was opened and needs the static scene."""
        if not self.per_mission or not mission or mission == self.mission:
            return False
        path = save_path(self.cfg.save, self.run_dir, mission)
        path.parent.mkdir(parents=True, exist_ok=True)
        rec = rr.RecordingStream(APP_ID, recording_id=mission)
        rec.set_sinks(rr.FileSink(path), default_blueprint=blueprint())
        with self._lock:
            old, self.mission_stream, self.mission = self.mission_stream, rec, mission
        if old is not None:
            old.disconnect()
        log.info("viz: saving mission %s to %s", mission, path)
        return True

    def streams(self) -> list[rr.RecordingStream]:
        with self._lock:
            return [s for s in (self.live, self.mission_stream) if s is not None]

    def log(self, stamp_ns: int, entries: Iterable[Entry]) -> None:
        """Log ``entries`` at ``stamp_ns`` (sim time as a duration from the world's
        start, otherwise wall time as a timestamp) on every open stream."""
        items = list(entries)
        if not items:
            return
        for rec in self.streams():
            set_time(rec, stamp_ns, self.sim_time)
            for e in items:
                rec.log(e.path, e.item, static=e.static)

    def log_static(self, rec: rr.RecordingStream, entries: Iterable[Entry]) -> None:
        for e in entries:
            rec.log(e.path, e.item, static=True)

    def close(self) -> None:
        """Stop the web viewer; flush and close every stream (writes the .rrd footers)."""
        if self.web is not None:
            self.web.close()
            self.web = None
        for rec in self.streams():
            rec.flush()
            rec.disconnect()
        with self._lock:
            self.live = self.mission_stream = None
