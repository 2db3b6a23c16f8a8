"""NMEA 0183 parsing and formatting for RTK receivers (pure: no I/O).

Parsing sits on top of pynmeagps; this module adds the checks pynmeagps leaves out
(it silently turns a malformed field into ``""``) so that every bad sentence becomes
one :class:`NmeaError` naming the sentence and what is wrong with it.

Formatting (for the simulated receiver) is in :mod:`services.gnss.nmea_format`.

Only the sentences the GNSS service uses are decoded: GGA (position, fix quality),
RMC (date, speed, course) and GST (noise statistics; Emlid Reach M2 emits it). Other
well-formed sentences parse to ``None`` so a mixed receiver stream never raises.

Units: degrees for latitude/longitude (WGS84, north/east positive), metres for
heights and standard deviations, m/s for speed, seconds since UTC midnight for time.
"""

from __future__ import annotations

import datetime as dt
import re

import msgspec
import pynmeagps
from pynmeagps.nmeahelpers import calc_checksum
from pynmeagps.nmeatypes_get import NMEA_PAYLOADS_GET

from common.messages.gnss import FixType as FixQuality

KNOT_MPS = 1852.0 / 3600.0


class NmeaError(ValueError):
    """A sentence that cannot be trusted: bad framing, checksum, field count or value."""


class Gga(msgspec.Struct, frozen=True, kw_only=True):
    """GGA: position and fix quality. ``alt_msl_m`` is above mean sea level; the
    ellipsoidal height is ``alt_msl_m + geoid_sep_m``. Position fields are ``None``
    when the receiver has no fix."""

    talker: str = "GN"
    time_s: float | None
    lat_deg: float | None
    lon_deg: float | None
    alt_msl_m: float | None
    geoid_sep_m: float | None = None
    quality: FixQuality
    num_sats: int = 0
    hdop: float | None = None
    diff_age_s: float | None = None
    base_id: int | None = None


class Rmc(msgspec.Struct, frozen=True, kw_only=True):
    """RMC: date, speed over ground (m/s) and course (degrees clockwise from true
    north, the NMEA convention, not REP-103). ``mode`` is the NMEA 2.3 mode letter
    (R = RTK fixed, F = RTK float, A = autonomous, D = differential, N = none)."""

    talker: str = "GN"
    time_s: float | None
    date: dt.date | None
    valid: bool
    lat_deg: float | None
    lon_deg: float | None
    speed_mps: float | None = None
    course_deg: float | None = None
    mode: str = ""


class Gst(msgspec.Struct, frozen=True, kw_only=True):
    """GST: the receiver's own 1-sigma error estimates in metres (orientation of the
    error ellipse's major axis in degrees clockwise from true north)."""

    talker: str = "GN"
    time_s: float | None
    rms_m: float | None = None
    std_major_m: float | None = None
    std_minor_m: float | None = None
    orient_deg: float | None = None
    std_lat_m: float | None = None
    std_lon_m: float | None = None
    std_alt_m: float | None = None


Sentence = Gga | Rmc | Gst

# Minimum field counts (after the address field). RMC grew a mode field in NMEA 2.3
# and a nav-status field in 4.10; accept the 2.x form too.
_MIN_FIELDS = {"GGA": 14, "RMC": 11, "GST": 8}
MAX_LEN = 200  # NMEA says 82; high-precision receivers exceed it, garbage exceeds this.


def parse_sentence(line: bytes | str) -> Sentence | None:
    """Parse one sentence (leading/trailing whitespace and CR/LF are ignored).

    Returns a :class:`Gga`, :class:`Rmc` or :class:`Gst`, or ``None`` for a valid
    sentence of another type. Raises :class:`NmeaError` (one line) otherwise.
    """
    text = _as_text(line)
    if not text.startswith("$"):
        raise NmeaError(f"NMEA sentence does not start with '$': {_clip(text)}")
    star = text.rfind("*")
    if star < 0 or len(text) - star != 3:
        raise NmeaError(f"NMEA sentence truncated (no '*hh' checksum): {_clip(text)}")
    body, given = text[1:star], text[star + 1 :].upper()
    fields = body.split(",")
    addr = fields[0]
    kind = addr[2:] if len(addr) == 5 and addr.isalnum() else addr
    want = calc_checksum(body)
    if given != want:
        raise NmeaError(f"{kind}: bad checksum *{given}, computed *{want}")
    if addr.startswith("P") or kind not in _MIN_FIELDS:
        return None  # proprietary or a type we do not use
    if len(addr) != 5 or not addr.isalnum():
        raise NmeaError(f"bad NMEA address field {addr!r}")
    payload = fields[1:]
    if len(payload) < _MIN_FIELDS[kind]:
        raise NmeaError(
            f"{kind} truncated: {len(payload)} fields, need {_MIN_FIELDS[kind]}: {_clip(text)}"
        )
    try:
        msg = pynmeagps.NMEAReader.parse(text.encode("ascii"), validate=pynmeagps.VALCKSUM)
    except (pynmeagps.NMEAParseError, pynmeagps.NMEATypeError, pynmeagps.NMEAMessageError) as e:
        raise NmeaError(f"{kind}: {e}") from None
    if msg is None:
        return None
    _check_fields(kind, payload, msg)
    talker = addr[:2]
    if kind == "GGA":
        return _gga(talker, payload, msg)
    if kind == "RMC":
        return _rmc(talker, payload, msg)
    return _gst(talker, msg)


def _as_text(line: bytes | str) -> str:
    if isinstance(line, bytes):
        try:
            line = line.decode("ascii")
        except UnicodeDecodeError:
            raise NmeaError(f"NMEA sentence is not ASCII: {line[:40]!r}") from None
    text = line.strip()
    if not text:
        raise NmeaError("empty NMEA sentence")
    if len(text) > MAX_LEN:
        raise NmeaError(f"NMEA sentence too long ({len(text)} chars): {_clip(text)}")
    return text


def _clip(text: str) -> str:
    return repr(text if len(text) <= 60 else text[:57] + "...")


# strptime and float() accept more than NMEA allows ("2334" as a date, "1e3" as a
# latitude), so the fixed-layout fields are matched exactly first.
_LAYOUTS = {
    "time": re.compile(r"\d{6}(\.\d{1,6})?"),
    "date": re.compile(r"\d{6}"),
    "lat": re.compile(r"\d{4}(\.\d+)?"),
    "lon": re.compile(r"\d{5}(\.\d+)?"),
}


def _check_fields(kind: str, payload: list[str], msg: pynmeagps.NMEAMessage) -> None:
    """pynmeagps decodes a malformed number as ``""``: a non-empty raw field that
    decoded to ``""``, or breaks its fixed layout, is a bad field."""
    for name, raw in zip(NMEA_PAYLOADS_GET[kind], payload, strict=False):
        layout = _LAYOUTS.get(name)
        bad_layout = layout is not None and raw and not layout.fullmatch(raw)
        if bad_layout or (raw and getattr(msg, name, "") == ""):
            raise NmeaError(f"{kind}: bad field {name} {raw!r}")


def _latlon(
    kind: str, payload: list[str], i: int, msg: pynmeagps.NMEAMessage
) -> tuple[float | None, float | None]:
    """Latitude/longitude in signed degrees from fields i..i+3, checked for range."""
    rlat, ns, rlon, ew = payload[i : i + 4]
    if not rlat and not rlon:
        return None, None
    if not (rlat and rlon):
        raise NmeaError(f"{kind}: only one of lat {rlat!r} / lon {rlon!r} is present")
    if ns not in ("N", "S") or ew not in ("E", "W"):
        raise NmeaError(f"{kind}: bad hemisphere {ns!r}/{ew!r}")
    for name, raw, limit in (("lat", rlat, 90.0), ("lon", rlon, 180.0)):
        dot = raw.find(".")
        minutes = float(raw[dot - 2 :] if dot >= 0 else raw[-2:])
        if minutes >= 60.0 or abs(float(getattr(msg, name))) > limit:
            raise NmeaError(f"{kind}: {name} {raw!r} out of range")
    return float(msg.lat), float(msg.lon)


def _time_s(value: object) -> float | None:
    if not isinstance(value, dt.time):
        return None
    # Integer microseconds first, so "000000.17" gives exactly 0.17.
    us = ((value.hour * 60 + value.minute) * 60 + value.second) * 1_000_000 + value.microsecond
    return us / 1e6


def _date(raw: str) -> dt.date:
    # strptime's %y pivots at 69; GNSS time starts in 1980 (GPS epoch), so pivot there.
    yy = int(raw[4:6])
    return dt.date(yy + (1900 if yy >= 80 else 2000), int(raw[2:4]), int(raw[0:2]))


def _opt_float(value: object) -> float | None:
    return None if value == "" or value is None else float(value)  # type: ignore[arg-type]


def _gga(talker: str, payload: list[str], msg: pynmeagps.NMEAMessage) -> Gga:
    try:
        quality = FixQuality(int(payload[5]))
    except ValueError:
        raise NmeaError(f"GGA: bad field quality {payload[5]!r}") from None
    lat, lon = _latlon("GGA", payload, 1, msg)
    if quality != FixQuality.NO_FIX and lat is None:
        raise NmeaError(f"GGA: quality {quality.name} but no position")
    station = payload[13]
    return Gga(
        talker=talker,
        time_s=_time_s(msg.time),
        lat_deg=lat,
        lon_deg=lon,
        alt_msl_m=_opt_float(msg.alt),
        geoid_sep_m=_opt_float(msg.sep),
        quality=quality,
        num_sats=int(payload[6] or 0),
        hdop=_opt_float(msg.HDOP),
        diff_age_s=_opt_float(msg.diffAge),
        base_id=int(station) if station.isdigit() else None,
    )


def _rmc(talker: str, payload: list[str], msg: pynmeagps.NMEAMessage) -> Rmc:
    if payload[1] not in ("A", "V"):
        raise NmeaError(f"RMC: bad field status {payload[1]!r}")
    lat, lon = _latlon("RMC", payload, 2, msg)
    spd = _opt_float(msg.spd)
    return Rmc(
        talker=talker,
        time_s=_time_s(msg.time),
        date=_date(payload[8]) if isinstance(msg.date, dt.date) else None,
        valid=payload[1] == "A",
        lat_deg=lat,
        lon_deg=lon,
        speed_mps=None if spd is None else spd * KNOT_MPS,
        course_deg=_opt_float(msg.cog),
        mode=payload[11] if len(payload) > 11 else "",
    )


def _gst(talker: str, msg: pynmeagps.NMEAMessage) -> Gst:
    return Gst(
        talker=talker,
        time_s=_time_s(msg.time),
        rms_m=_opt_float(msg.rangeRms),
        std_major_m=_opt_float(msg.stdMajor),
        std_minor_m=_opt_float(msg.stdMinor),
        orient_deg=_opt_float(msg.orient),
        std_lat_m=_opt_float(msg.stdLat),
        std_lon_m=_opt_float(msg.stdLong),
        std_alt_m=_opt_float(msg.stdAlt),
    )
