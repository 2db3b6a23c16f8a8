"""The simulated Reach M2's sentences (checked by pynmeagps, a parser we did not
write) and the fix builder meeting a Reach's sentence order."""

from __future__ import annotations

import math

import pynmeagps
import pytest

from common.clock import NS
from common.geo import FieldFrame
from common.messages.gnss import FixType
from common.messages.sim import SimAntennas
from services.gnss.nmea import FixQuality, Gga, Gst, Rmc, parse_sentence
from services.gnss.reach import ReachM2
from services.gnss.rtk_model import STATES, RtkModelConfig
from services.gnss.solution import FixBuilder

FRAME = FieldFrame(33.717028, -83.308083, 200.0, 90.0)
HELD = RtkModelConfig(rates_per_s=[[0.0] * len(STATES) for _ in STATES])


def nmea(text: str) -> list[pynmeagps.NMEAMessage]:
    out = []
    for line in text.splitlines():
        msg = pynmeagps.NMEAReader.parse(line.encode(), validate=pynmeagps.VALCKSUM)
        assert msg is not None, line
        out.append(msg)
    return out


def moving(k: int, speed: float = 1.0) -> SimAntennas:
    """Epoch k (10 Hz) of the antennas driving along field +x at ``speed`` m/s."""
    x = speed * k / 10
    return SimAntennas(stamp_ns=k * NS // 10, p1=(x, 0.0, 1.0), p2=(x + 0.95, 0.0, 1.0))


def test_an_epoch_is_rmc_gga_gst_vtg_as_a_reach_sends_it() -> None:
    rx = ReachM2(HELD, 1, 1, FRAME)
    rx.epoch(moving(0))
    text = rx.epoch(moving(1))
    msgs = nmea(text)
    assert [m.identity for m in msgs] == ["GNRMC", "GNGGA", "GNGST", "GNVTG"]
    rmc, gga, gst, vtg = msgs
    # NMEA 2.3 RMC: ends at the mode letter; RTK fixed is "R"
    assert text.splitlines()[0].split("*")[0].count(",") == 12
    assert rmc.posMode == "R" and rmc.status == "A"
    assert gga.quality == 4 and gga.time == rmc.time
    # the Reach leaves the error ellipse empty and reports lat/lon/alt sigmas
    assert gst.stdMajor == "" and 0.005 < gst.stdLat < 0.01
    e, n = FRAME.field_to_map(1.0, 0.0)
    course = math.degrees(math.atan2(float(e), float(n))) % 360
    assert vtg.sogk == pytest.approx(3.6, abs=1e-3)
    assert vtg.cogt == pytest.approx(course, abs=1e-2) and rmc.cog == vtg.cogt
    assert vtg.posMode == "R"


def test_standing_still_leaves_the_course_empty() -> None:
    rx = ReachM2(HELD, 1, 1, FRAME)
    rx.epoch(moving(0, speed=0.0))
    rmc, *_, vtg = nmea(rx.epoch(moving(1, speed=0.0)))
    assert rmc.cog == "" and vtg.cogt == "" and vtg.sogn == 0.0


def test_no_fix_sends_a_void_rmc_and_a_gga_without_position_our_parser_accepts() -> None:
    rx = ReachM2(
        RtkModelConfig(initial_state=FixQuality.NO_FIX, rates_per_s=HELD.rates_per_s), 1, 2, FRAME
    )
    text = rx.epoch(moving(0))
    parsed = [parse_sentence(line) for line in text.splitlines()]  # raises if not
    rmc, gga = parsed
    assert isinstance(rmc, Rmc) and not rmc.valid and rmc.mode == "N"
    assert isinstance(gga, Gga) and gga.quality == FixQuality.NO_FIX and gga.lat_deg is None


def test_gp_talker() -> None:
    rx = ReachM2(HELD, 1, 1, FRAME, talker="GP")
    assert {m.talker for m in nmea(rx.epoch(moving(0)))} == {"GP"}


def gga(t: float, q: FixQuality) -> Gga:
    return Gga(time_s=t, lat_deg=33.7, lon_deg=-83.3, alt_msl_m=200.0, quality=q)


def gst(t: float, sd: float) -> Gst:
    return Gst(time_s=t, std_lat_m=sd, std_lon_m=sd, std_alt_m=2 * sd)


def test_gst_after_gga_is_not_carried_across_a_change_of_fix_type() -> None:
    fb = FixBuilder(1, {"FIX": 0.014, "FLOAT": 0.25})
    fb.on_gga(gga(0.0, FixQuality.FIX), 0)
    fb.on_gst(gst(0.0, 0.007))
    f = fb.on_gga(gga(0.1, FixQuality.FIX), 0)  # the previous epoch's GST: same type
    assert f is not None and f.position_covariance[0] == pytest.approx(0.007**2)
    fb.on_gst(gst(0.1, 0.007))
    f = fb.on_gga(gga(0.2, FixQuality.FLOAT), 0)  # lost the fix: not 7 mm
    assert f is not None and f.fix_type == FixType.FLOAT
    assert f.position_covariance[0] == pytest.approx(0.25**2)
    fb.on_gst(gst(0.2, 0.25))
    f = fb.on_gga(gga(0.3, FixQuality.FLOAT), 0)
    assert f is not None and f.position_covariance[0] == pytest.approx(0.25**2)


def test_gst_before_gga_of_the_same_epoch_is_used() -> None:
    fb = FixBuilder(1, {"FIX": 0.014})
    fb.on_gst(gst(0.0, 0.009))
    f = fb.on_gga(gga(0.0, FixQuality.FIX), 0)
    assert f is not None and f.position_covariance[0] == pytest.approx(0.009**2)
