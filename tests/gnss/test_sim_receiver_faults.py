"""The simulated receiver under the faults the simulator injects through
``SimAntennas``: an outage sends nothing, a forced float reports RTK float with float
noise, multipath moves the position and keeps the quality; outside a fault the
receiver's output is the same as without it."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any, cast

import msgspec
import numpy as np

from common import keys
from common.clock import NS
from common.geo import FieldFrame
from common.messages.gnss import FixType
from common.messages.sim import SimAntennas
from common.transport import Bus
from services.gnss.config import AntennaConfig, GnssConfig
from services.gnss.nmea import Gga, Gst, parse_sentence
from services.gnss.receiver import SimReceiver
from services.gnss.rtk_model import STATES, RtkModelConfig

FRAME = FieldFrame(33.717028, -83.308083, 200.0, 90.0)
# the state chain held in FIX, so every change of quality is the fault's
CFG = GnssConfig(
    backend="sim", rtk=RtkModelConfig(rates_per_s=[[0.0] * len(STATES) for _ in STATES])
)
P1, P2 = (10.0, 2.0, 1.3), (10.95, 2.0, 1.3)


class FakeBus:
    """What SimReceiver needs of a bus: the subscription to the antenna truth."""

    def __init__(self) -> None:
        self.on_truth: Callable[[SimAntennas], None] | None = None

    def subscribe(self, topic: Any, callback: Callable[[SimAntennas], None]) -> None:
        assert topic is keys.SIM_ANTENNAS
        self.on_truth = callback


def receiver(antenna: int) -> tuple[SimReceiver, FakeBus]:
    bus = FakeBus()
    rx = SimReceiver(CFG, AntennaConfig(id=antenna), cast(Bus, bus), FRAME)
    return rx, bus


def truth(k: int, **faults: Any) -> SimAntennas:
    """Epoch ``k`` of a 10 Hz stream (sim time k / 10 s)."""
    return SimAntennas(stamp_ns=k * NS // 10, frame_id="field", p1=P1, p2=P2, **faults)


def parse(text: str) -> tuple[Gga, Gst | None]:
    out = [parse_sentence(line) for line in text.splitlines()]
    ggas = [s for s in out if isinstance(s, Gga)]
    gsts = [s for s in out if isinstance(s, Gst)]
    assert len(ggas) == 1, text
    return ggas[0], (gsts[0] if gsts else None)


def sd(gst: Gst | None) -> float:
    """The reported 1-sigma latitude error (m)."""
    assert gst is not None and gst.std_lat_m is not None
    return gst.std_lat_m


def error_en(gga: Gga, p: tuple[float, float, float]) -> tuple[float, float]:
    """Reported minus true position, east and north (m)."""
    assert gga.lat_deg is not None and gga.lon_deg is not None
    e, n, _ = FRAME.wgs84_to_map(gga.lat_deg, gga.lon_deg, 0.0)
    te, tn = FRAME.field_to_map(p[0], p[1])
    return float(e - te), float(n - tn)


def test_no_fault_is_rtk_fixed_within_centimetres() -> None:
    rx, _ = receiver(1)
    gga, gst = parse(rx.epoch(truth(0)))
    assert gga.quality == FixType.FIX and sd(gst) < 0.01
    assert np.hypot(*error_en(gga, P1)) < 0.05


def test_outage_sends_nothing_for_its_antenna_only() -> None:
    rx1, bus1 = receiver(1)
    rx2, _ = receiver(2)
    assert rx1.epoch(truth(0, outage1=True)) == ""
    assert parse(rx2.epoch(truth(0, outage1=True)))[0].quality == FixType.FIX
    assert rx2.epoch(truth(1, outage2=True)) == ""
    # nothing is queued for an epoch in an outage: the next bytes are the next epoch's
    assert bus1.on_truth is not None
    bus1.on_truth(truth(1, outage1=True, outage2=True))
    bus1.on_truth(truth(2))
    data = rx1.read(threading.Event())
    assert parse(data.decode()) and parse(data.decode())[0].time_s == 0.2


def test_forced_float_reports_quality_5_with_float_noise() -> None:
    rx, _ = receiver(2)
    float_sd = CFG.rtk.float_.h_const_m + 1e-6 * CFG.rtk.float_.h_ppm * CFG.rtk.baseline_m
    errors = []
    for k in range(600):  # a minute: two float correlation times
        gga, gst = parse(rx.epoch(truth(k, force_float2=True, force_float1=False)))
        assert gga.quality == FixType.FLOAT
        assert abs(sd(gst) - float_sd) < 1e-3
        errors.append(error_en(gga, P2))
    rms = float(np.sqrt(np.mean(np.square(errors))))
    assert 0.05 < rms < 1.0, rms  # decimetres, not the fix's millimetres
    gga, _ = parse(rx.epoch(truth(600)))
    assert gga.quality == FixType.FIX and np.hypot(*error_en(gga, P2)) < 0.05


def test_multipath_moves_one_antenna_and_keeps_it_fixed() -> None:
    rx1, _ = receiver(1)
    rx2, _ = receiver(2)
    lie = truth(0, offset1=(0.5, -0.25))
    g1, gst = parse(rx1.epoch(lie))
    g2, _ = parse(rx2.epoch(lie))
    assert g1.quality == FixType.FIX and sd(gst) < 0.01
    e, n = error_en(g1, P1)
    assert abs(e - 0.5) < 0.05 and abs(n + 0.25) < 0.05
    assert np.hypot(*error_en(g2, P2)) < 0.05


def test_outside_a_fault_the_output_is_unchanged() -> None:
    clean, _ = receiver(1)
    faulty, _ = receiver(1)
    window = {"force_float1": True, "offset1": (1.0, 1.0)}
    for k in range(50):
        a = clean.epoch(truth(k))
        b = faulty.epoch(truth(k, **window) if 10 <= k < 20 else truth(k))
        assert (a == b) == (not 10 <= k < 20), k
    for k in range(50, 60):  # and through an outage
        gone = msgspec.structs.replace(truth(k), outage1=k < 55)
        a, b = clean.epoch(truth(k)), faulty.epoch(gone)
        assert b == ("" if k < 55 else a)
