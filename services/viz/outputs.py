"""Where the dashboard's data goes: rerun recording streams and their sinks.

One *live* stream for the service's lifetime feeds the gRPC server (and the web
viewer), a viewer we connect to, and a fixed ``save`` path. A ``save`` path holding
``{mission}`` gets a stream of its own per mission, opened when the mission starts
and closed (footer written) when the next starts or the service stops.

The rerun SDK does its encoding and I/O on its own threads; ``log`` only hands data
over. Rerun's analytics live in its viewers, never in the SDK: the native viewer
reads them from ``rerun analytics disable``, the web viewer from the browser.
"""

from __future__ import annotations

import logging
import socket
import threading
from collections.abc import Iterable
from pathlib import Path
from urllib.parse import quote

import rerun as rr

from services.viz.config import VizConfig
from services.viz.scene import Entry, blueprint

APP_ID = "phenorover"
TIMELINE = "time"

log = logging.getLogger("viz")


def port_free(host: str, port: int) -> bool:
    """Whether ``host``:``port`` can be bound now (rerun's server only logs a failure)."""
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError:
            return False
    return True


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
    def __init__(self, cfg: VizConfig, run_dir: Path, sim_time: bool) -> None:
        self.cfg, self.run_dir, self.sim_time = cfg, run_dir, sim_time
        self.per_mission = "{mission}" in cfg.save
        self.live: rr.RecordingStream | None = None
        self.mission_stream: rr.RecordingStream | None = None
        self.mission = ""
        self.viewer_url = ""
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
            self.live = rr.RecordingStream(APP_ID, send_properties=True)
            self.live.set_sinks(*sinks, default_blueprint=blueprint())

    def _serve_web(self, grpc_uri: str) -> None:
        cfg = self.cfg
        host = cfg.advertise or (socket.gethostname() if cfg.bind == "0.0.0.0" else cfg.bind)
        url = grpc_uri.replace("127.0.0.1", host).replace("0.0.0.0", host)
        if cfg.web_port and port_free("0.0.0.0", cfg.web_port):
            rr.serve_web_viewer(web_port=cfg.web_port, open_browser=False, connect_to=url)
            self.viewer_url = f"http://{host}:{cfg.web_port}/?url={quote(url, safe='')}"
            log.info("viz: web viewer at %s", self.viewer_url)
        elif cfg.web_port:
            log.error("viz: cannot serve the web viewer: port %d is in use", cfg.web_port)
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
            if self.sim_time:
                rec.set_time(TIMELINE, duration=stamp_ns * 1e-9)
            else:
                rec.set_time(TIMELINE, timestamp=stamp_ns * 1e-9)
            for e in items:
                rec.log(e.path, e.item, static=e.static)

    def log_static(self, rec: rr.RecordingStream, entries: Iterable[Entry]) -> None:
        for e in entries:
            rec.log(e.path, e.item, static=True)

    def close(self) -> None:
        """Flush and close every stream (writes the .rrd footers)."""
        for rec in self.streams():
            rec.flush()
            rec.disconnect()
        with self._lock:
            self.live = self.mission_stream = None
