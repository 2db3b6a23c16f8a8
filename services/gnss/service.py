"""The gnss service's Zenoh shell: one reader thread per receiver, fixes and the
compass heading out on the bus."""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable

from common import keys
from common.field_geojson import load_frame
from common.messages.gnss import NavSatFix
from common.service import Context
from services.gnss.compass import Compass
from services.gnss.config import GnssConfig
from services.gnss.nmea import Gga, Gst, NmeaError, parse_sentence
from services.gnss.nmea_stream import LineSplitter
from services.gnss.pairing import EpochPairer
from services.gnss.receiver import Receiver, open_receiver
from services.gnss.solution import FixBuilder, heading


class GnssService:
    def __init__(self, ctx: Context, cfg: GnssConfig) -> None:
        self.ctx, self.cfg = ctx, cfg
        self.frame = load_frame(ctx.field, ctx.clock)
        self.compass = Compass.of(ctx.robot, cfg.compass)
        self.heading_pub = ctx.bus.publisher(keys.GNSS_HEADING)
        self.fix_pubs = {
            a.id: ctx.bus.publisher(keys.GNSS_FIX.at(antenna=a.id)) for a in cfg.antennas
        }
        self.receivers = [open_receiver(cfg, a, ctx.bus, self.frame) for a in cfg.antennas]
        # bytes between sentences that are not NMEA (line noise) are skipped by the
        # splitter, never parsed: counted here, as bad sentences are in decode_errors
        self.splitters = {rx.antenna: LineSplitter() for rx in self.receivers}
        for antenna, sp in self.splitters.items():
            ctx.bus.report(f"antenna{antenna}_garbage_bytes", _count(sp))
        self.pairs = EpochPairer()

    def _on_fix(self, epoch: float, fix: NavSatFix) -> None:
        self.fix_pubs[fix.antenna].put(fix)
        if (pair := self.pairs.add(epoch, fix)) is not None:
            self.heading_pub.put(heading(*pair, self.frame, self.compass))

    def _feed(self, antenna: int, builder: FixBuilder, data: bytes) -> None:
        """Take in what antenna ``antenna``'s receiver sent: its fixes out."""
        where = f"gnss/{antenna}/nmea"
        for line in self.splitters[antenna].feed(data):
            try:
                s = parse_sentence(line)
            except NmeaError as exc:
                if self.ctx.bus.decode_stats.record(where, str(exc)):
                    self.ctx.log.warning("antenna %d: dropped sentence: %s", antenna, exc)
                continue
            if isinstance(s, Gst):
                builder.on_gst(s)
            elif isinstance(s, Gga) and s.time_s is not None:
                fix = builder.on_gga(s, self.ctx.clock.now_ns())
                if fix is not None:
                    self._on_fix(s.time_s, fix)

    def _read(self, rx: Receiver, builder: FixBuilder, stop: threading.Event) -> None:
        while not stop.is_set():
            self._feed(rx.antenna, builder, rx.read(stop))

    def run(self, stop: threading.Event) -> None:
        threads = []
        for rx in self.receivers:
            builder = FixBuilder(rx.antenna, self.cfg.fallback_sigma_m)
            # a receiver that delivers (the simulator's: in lockstep, at its step) is
            # taken in as it does; a link is read by a thread of its own
            if not rx.deliver(functools.partial(self._feed, rx.antenna, builder)):
                threads.append(
                    threading.Thread(
                        target=self._read, args=(rx, builder, stop), name=f"gnss{rx.antenna}"
                    )
                )
        for t in threads:
            t.start()
        stop.wait()
        for t in threads:
            t.join(timeout=2.0)
        for rx in self.receivers:
            rx.close()


def _count(splitter: LineSplitter) -> Callable[[], int]:
    return lambda: splitter.dropped_bytes


def build(ctx: Context, cfg: GnssConfig) -> GnssService:
    return GnssService(ctx, cfg)
