"""Two simulated Emlid Reach M2 receivers on their real wires, for hardware-in-the-
loop runs: ``python -m services.gnss.sim.reach --manifest M`` (``[services.reach-sim]``).

It follows the simulator's antenna truth (``sim/device/antennas``) and sends what a
Reach M2 sends on its NMEA position output (:class:`services.gnss.reach.ReachM2`, the
code the gnss ``sim`` backend runs) on a TCP server and/or a serial pseudo-terminal
per antenna, so the gnss service's hardware backends (``nmea-tcp``, ``nmea-serial``)
read the simulated robot unchanged.

Faults of the wires, for tests: scheduled in sim time (``[services.reach-sim.faults]``)
or at run time by signal: SIGUSR1 drops every TCP link (the servers keep listening),
SIGUSR2 writes garbage into the serial lines. Either takes effect before the next
epoch is sent.
"""

from __future__ import annotations

import bisect
import signal
import threading
from pathlib import Path

from common import keys
from common.clock import NS
from common.field_geojson import load_frame
from common.messages.sim import SimAntennas
from common.service import Context, run
from services.gnss.reach import ReachM2
from services.gnss.sim.config import ReachSimConfig
from services.gnss.sim.wire import PtyLine, TcpFanout


class _Schedule:
    """Sim times at which a fault fires, each once, in order."""

    def __init__(self, times_s: list[float]) -> None:
        self._times = sorted(times_s)

    def due(self, now_s: float) -> bool:
        n = bisect.bisect_right(self._times, now_s)
        del self._times[:n]
        return n > 0


class ReachSim:
    def __init__(self, ctx: Context, cfg: ReachSimConfig) -> None:
        self.ctx, self.cfg = ctx, cfg
        frame = load_frame(ctx.field, ctx.clock)
        self.rovers = {
            o.id: ReachM2(cfg.rtk, cfg.seed, o.id, frame, cfg.talker) for o in cfg.outputs
        }
        self.servers: dict[int, TcpFanout] = {}
        self.lines: dict[int, PtyLine] = {}
        for o in cfg.outputs:
            if o.tcp_port is not None:
                srv = TcpFanout(cfg.host, o.tcp_port, f"antenna {o.id} TCP")
                self.servers[o.id] = srv
                ctx.log.info("antenna %d: NMEA TCP server on %s:%d", o.id, srv.host, srv.port)
            if o.pty:
                line = PtyLine(Path(o.pty))
                self.lines[o.id] = line
                ctx.log.info("antenna %d: NMEA serial line %s -> %s", o.id, o.pty, line.device)
        self._drops = _Schedule(cfg.faults.drop_links_at_s)
        self._noise = _Schedule(cfg.faults.garbage_at_s)
        self._drop_now = threading.Event()
        self._garbage_now = threading.Event()
        self._lock = threading.Lock()
        self._closed = False
        self.epochs = self.links_dropped = self.garbage_writes = 0
        bus = ctx.bus
        bus.report("epochs", lambda: self.epochs)
        bus.report("links_dropped", lambda: self.links_dropped)
        bus.report("garbage_writes", lambda: self.garbage_writes)
        bus.report("tcp_clients", lambda: sum(s.clients for s in self.servers.values()))
        bus.report("serial_overruns", lambda: sum(ln.overruns for ln in self.lines.values()))
        bus.subscribe(keys.SIM_ANTENNAS, self._on_truth)

    def hook_signals(self) -> None:
        """SIGUSR1 drops the TCP links, SIGUSR2 puts garbage on the serial lines (from
        the process's main thread only, as Python requires)."""
        signal.signal(signal.SIGUSR1, lambda *_: self._drop_now.set())
        signal.signal(signal.SIGUSR2, lambda *_: self._garbage_now.set())

    def _faults(self, now_s: float) -> None:
        # "|", not "or": a schedule consumes what is due whether or not a signal came
        if self._drops.due(now_s) | self._drop_now.is_set():
            self._drop_now.clear()
            n = sum(s.drop_all() for s in self.servers.values())
            self.links_dropped += n
            self.ctx.log.warning("fault: dropped %d TCP link(s) at sim %.2f s", n, now_s)
        if self._noise.due(now_s) | self._garbage_now.is_set():
            self._garbage_now.clear()
            junk = self.cfg.faults.garbage.encode("latin-1")
            for line in self.lines.values():
                line.send(junk)
            self.garbage_writes += 1
            self.ctx.log.warning(
                "fault: %d garbage bytes on %d serial line(s) at sim %.2f s",
                len(junk),
                len(self.lines),
                now_s,
            )

    def _on_truth(self, msg: SimAntennas) -> None:
        # one writer: epochs and faults reach the wires in order, never interleaved
        with self._lock:
            if self._closed:
                return
            self._faults(msg.stamp_ns / NS)
            for antenna, rover in self.rovers.items():
                data = rover.epoch(msg).encode("ascii")
                if not data:
                    continue  # outage: the receiver sends nothing
                if antenna in self.servers:
                    self.servers[antenna].send(data)
                if antenna in self.lines:
                    self.lines[antenna].send(data)
            self.epochs += 1

    def run(self, stop: threading.Event) -> None:
        threads = [
            threading.Thread(target=s.serve, args=(stop,), name=f"reach{a}-tcp", daemon=True)
            for a, s in self.servers.items()
        ]
        for t in threads:
            t.start()
        stop.wait()
        with self._lock:
            self._closed = True
            for srv in self.servers.values():
                srv.close()
            for line in self.lines.values():
                line.close()
        for t in threads:
            t.join(timeout=2.0)


def build(ctx: Context, cfg: ReachSimConfig) -> ReachSim:
    sim = ReachSim(ctx, cfg)
    sim.hook_signals()
    return sim


if __name__ == "__main__":
    run("reach-sim", ReachSimConfig, build)
