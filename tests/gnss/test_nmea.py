"""NMEA parsing (real-world sentences, bad input) and format -> parse round trips."""

from __future__ import annotations

import contextlib
import datetime as dt

import pytest
from hypothesis import given
from hypothesis import strategies as st
from pynmeagps.nmeahelpers import calc_checksum as checksum

from services.gnss.nmea import FixQuality, Gga, Gst, NmeaError, Rmc, parse_sentence
from services.gnss.nmea_format import format_gga, format_gst, format_rmc
from services.gnss.nmea_stream import LineSplitter

# Published examples (NovAtel GPGGA/GPGST docs, the classic NMEA RMC/GGA examples).
NOVATEL_GGA = (
    "$GPGGA,172814.0,3723.46587704,N,12202.26957864,W,2,6,1.2,18.893,M,-25.669,M,2.0,0031*4F"
)
NOVATEL_GST = "$GPGST,172814.0,0.006,0.023,0.020,273.6,0.023,0.020,0.031*6A"
CLASSIC_RMC = "$GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W*6A"
CLASSIC_GGA = "$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47"
NO_FIX_GGA = "$GPGGA,,,,,,0,00,99.99,,,,,,*48"
GSA = "$GNGSA,A,3,80,71,73,79,69,,,,,,,,1.83,1.09,1.47*17"


def with_checksum(body: str) -> str:
    return f"${body}*{checksum(body)}"


def test_novatel_gga() -> None:
    g = parse_sentence(NOVATEL_GGA)
    assert isinstance(g, Gga)
    assert g.talker == "GP"
    assert g.time_s == pytest.approx(17 * 3600 + 28 * 60 + 14)
    assert g.lat_deg == pytest.approx(37 + 23.46587704 / 60, abs=1e-9)
    assert g.lon_deg == pytest.approx(-(122 + 2.26957864 / 60), abs=1e-9)
    assert g.quality == FixQuality.DGPS
    assert (g.num_sats, g.hdop, g.alt_msl_m, g.geoid_sep_m) == (6, 1.2, 18.893, -25.669)
    assert (g.diff_age_s, g.base_id) == (2.0, 31)


def test_novatel_gst() -> None:
    s = parse_sentence(NOVATEL_GST)
    assert isinstance(s, Gst)
    assert (s.std_lat_m, s.std_lon_m, s.std_alt_m) == (0.023, 0.020, 0.031)
    assert s.orient_deg == 273.6


def test_classic_rmc_and_gga() -> None:
    r = parse_sentence(CLASSIC_RMC.encode() + b"\r\n")
    assert isinstance(r, Rmc)
    assert r.valid and r.date == dt.date(1994, 3, 23)
    assert r.speed_mps == pytest.approx(22.4 * 1852 / 3600)
    assert r.course_deg == 84.4
    g = parse_sentence(CLASSIC_GGA)
    assert isinstance(g, Gga) and g.quality == FixQuality.SINGLE and g.num_sats == 8


def test_no_fix_gga_has_no_position() -> None:
    g = parse_sentence(NO_FIX_GGA)
    assert isinstance(g, Gga)
    assert g.quality == FixQuality.NO_FIX
    assert g.lat_deg is None and g.lon_deg is None and g.time_s is None


@pytest.mark.parametrize(("quality", "state"), [(4, FixQuality.FIX), (5, FixQuality.FLOAT)])
def test_rtk_states(quality: int, state: FixQuality) -> None:
    body = (
        f"GNGGA,101530.20,4025.6432112,N,08654.9123456,W,{quality},"
        "24,0.6,190.123,M,-33.4,M,1.2,0000"
    )
    g = parse_sentence(with_checksum(body))
    assert isinstance(g, Gga) and g.quality == state
    assert g.time_s == pytest.approx(10 * 3600 + 15 * 60 + 30.2)


def test_other_sentences_are_none() -> None:
    assert parse_sentence(GSA) is None
    assert parse_sentence(with_checksum("PEMLID,1,2,3")) is None


@pytest.mark.parametrize(
    ("line", "words"),
    [
        (NOVATEL_GGA[:-2] + "4E", "bad checksum"),
        (NOVATEL_GGA[:40], "truncated"),
        (with_checksum("GPGGA,172814.0,3723.4658,N,12202.2695,W,1,8"), "truncated"),
        (with_checksum("GPGGA,172814.0,37x3.4658,N,12202.2695,W,1,8,1,1,M,1,M,,"), "bad field lat"),
        (
            with_checksum("GPGGA,17x814.0,3723.4658,N,12202.2695,W,1,8,1,1,M,1,M,,"),
            "bad field time",
        ),
        (with_checksum("GPGGA,172814.0,3723.4658,N,12202.2695,W,9,8,1,1,M,1,M,,"), "quality"),
        (with_checksum("GPGGA,172814.0,3723.4658,N,12202.2695,W,Q,8,1,1,M,1,M,,"), "quality"),
        (with_checksum("GPGGA,172814.0,9123.4658,N,12202.2695,W,1,8,1,1,M,1,M,,"), "out of range"),
        (with_checksum("GPGGA,172814.0,3763.4658,N,12202.2695,W,1,8,1,1,M,1,M,,"), "out of range"),
        (with_checksum("GPGGA,172814.0,3723.4658,X,12202.2695,W,1,8,1,1,M,1,M,,"), "hemisphere"),
        (with_checksum("GPGGA,172814.0,,,,,4,8,1,1,M,1,M,,"), "no position"),
        (with_checksum("GPRMC,123519,Z,4807.038,N,01131.000,E,022.4,084.4,230394,,"), "status"),
        ("GPGGA,1,2*00", r"start with '\$'"),
        ("", "empty"),
        (b"$GPGGA,\xff\xfe*00", "not ASCII"),
        ("$" + "A" * 300 + "*00", "too long"),
    ],
)
def test_bad_input_raises_one_line_error(line: str | bytes, words: str) -> None:
    with pytest.raises(NmeaError, match=words) as info:
        parse_sentence(line)
    assert "\n" not in str(info.value)


# --- round trips ---

lat = st.floats(-89.999999, 89.999999, allow_nan=False)
lon = st.floats(-179.999999, 179.999999, allow_nan=False)
tod = st.integers(0, 8_639_999).map(lambda cs: cs / 100.0)
opt_m = st.none() | st.floats(0.0, 99.0).map(lambda v: round(v, 4))


@given(
    lat=lat,
    lon=lon,
    t=tod,
    alt=st.floats(-400.0, 9000.0).map(lambda v: round(v, 4)),
    quality=st.sampled_from([q for q in FixQuality if q != FixQuality.NO_FIX]),
    sats=st.integers(0, 99),
    hdop=st.floats(0.0, 99.0).map(lambda v: round(v, 2)),
    age=st.none() | st.floats(0.0, 999.0).map(lambda v: round(v, 1)),
    base=st.none() | st.integers(0, 1023),
)
def test_gga_round_trip(
    lat: float,
    lon: float,
    t: float,
    alt: float,
    quality: FixQuality,
    sats: int,
    hdop: float,
    age: float | None,
    base: int | None,
) -> None:
    g = Gga(
        time_s=t,
        lat_deg=lat,
        lon_deg=lon,
        alt_msl_m=alt,
        geoid_sep_m=-12.5,
        quality=quality,
        num_sats=sats,
        hdop=hdop,
        diff_age_s=age,
        base_id=base,
    )
    back = parse_sentence(format_gga(g))
    assert isinstance(back, Gga)
    # 1e-9 deg is 0.1 mm: the sim's mm-level noise survives the trip.
    assert back.lat_deg == pytest.approx(lat, abs=1e-9)
    assert back.lon_deg == pytest.approx(lon, abs=1e-9)
    assert back.time_s == pytest.approx(t, abs=1e-6)
    exact = ("quality", "num_sats", "hdop", "alt_msl_m", "geoid_sep_m", "diff_age_s", "base_id")
    assert [getattr(back, f) for f in exact] == [getattr(g, f) for f in exact]


@given(
    lat=lat,
    lon=lon,
    t=tod,
    date=st.dates(dt.date(1980, 1, 6), dt.date(2079, 12, 31)),
    valid=st.booleans(),
    speed=st.floats(0.0, 50.0),
    course=st.floats(0.0, 359.999).map(lambda v: round(v, 3)),
    mode=st.sampled_from("ADEFNRS"),
)
def test_rmc_round_trip(
    lat: float,
    lon: float,
    t: float,
    date: dt.date,
    valid: bool,
    speed: float,
    course: float,
    mode: str,
) -> None:
    r = Rmc(
        time_s=t,
        date=date,
        valid=valid,
        lat_deg=lat,
        lon_deg=lon,
        speed_mps=speed,
        course_deg=course,
        mode=mode,
    )
    back = parse_sentence(format_rmc(r))
    assert isinstance(back, Rmc)
    assert (back.date, back.valid, back.mode, back.course_deg) == (date, valid, mode, course)
    assert back.speed_mps == pytest.approx(speed, abs=1e-4)
    assert back.lat_deg == pytest.approx(lat, abs=1e-9)


@given(t=tod, a=opt_m, b=opt_m, c=opt_m, d=opt_m)
def test_gst_round_trip(
    t: float, a: float | None, b: float | None, c: float | None, d: float | None
) -> None:
    s = Gst(time_s=t, rms_m=a, std_lat_m=b, std_lon_m=c, std_alt_m=d)
    back = parse_sentence(format_gst(s))
    assert back == s


def test_no_fix_round_trip() -> None:
    g = Gga(time_s=1.0, lat_deg=None, lon_deg=None, alt_msl_m=None, quality=FixQuality.NO_FIX)
    assert parse_sentence(format_gga(g)) == g


# --- streams ---


def test_splitter_resyncs_after_garbage_and_split_reads() -> None:
    gga, gst = NOVATEL_GGA.encode(), NOVATEL_GST.encode()
    stream = (
        b"\x00\xffnoise" + gga + b"\r\n$GPGGA,17281" + gst + b"\r\n" + b"junk\r\n" + gga + b"\n"
    )
    sp = LineSplitter()
    lines: list[bytes] = []
    for i in range(0, len(stream), 7):  # arbitrary read boundaries
        lines += sp.feed(stream[i : i + 7])
    assert lines == [gga, gst, gga]
    assert sp.dropped_bytes == len(b"\x00\xffnoise") + len(b"$GPGGA,17281") + len(b"junk")


def test_splitter_drops_overlong_runs() -> None:
    sp = LineSplitter(max_len=100)
    assert sp.feed(b"$" + b"A" * 500) == []
    assert sp.feed(b"\r\n" + NOVATEL_GST.encode() + b"\r\n") == [NOVATEL_GST.encode()]


# --- fuzz: bad input raises NmeaError, nothing else ---


@given(st.binary(max_size=120))
def test_arbitrary_bytes_never_crash(data: bytes) -> None:
    with contextlib.suppress(NmeaError):
        parse_sentence(data)


@given(
    base=st.sampled_from([NOVATEL_GGA, NOVATEL_GST, CLASSIC_RMC, CLASSIC_GGA]),
    pos=st.integers(0, 80),
    junk=st.text(alphabet="0123456789.,-+NSEWAVMx ", max_size=6),
    cut=st.integers(0, 6),
)
def test_mutated_sentences_with_valid_checksum_never_crash(
    base: str, pos: int, junk: str, cut: int
) -> None:
    body = base[1 : base.index("*")]
    pos = min(pos, len(body))
    mutated = body[:pos] + junk + body[pos + cut :]
    with contextlib.suppress(NmeaError):
        parse_sentence(with_checksum(mutated))
