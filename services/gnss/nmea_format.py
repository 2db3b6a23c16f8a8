"""NMEA 0183 formatting, the inverse of :func:`services.gnss.nmea.parse_sentence`.

The simulated receiver formats its fixes with these so that the sim path runs
through the same parser as a real receiver. Sentences carry their checksum
(pynmeagps') and end in CR/LF; ``None`` fields become empty fields. The fields are
written here rather than by pynmeagps' ``NMEAMessage.serialize``, which writes a
position to 7 decimals of a minute at most (0.19 mm; these write 8), a hemisphere
letter beside an empty position, and RMC only in its NMEA 4.10 form, where an Emlid
Reach sends the 2.3 one.
"""

from __future__ import annotations

import math

import msgspec
from pynmeagps.nmeahelpers import calc_checksum

from services.gnss.nmea import KNOT_MPS, Gga, Gst, Rmc


class Vtg(msgspec.Struct, frozen=True, kw_only=True):
    """VTG: course over ground (degrees clockwise from true north) and speed (m/s).
    Formatted only: the gnss service has no use for it, so the parser checks its
    framing and checksum and passes over it."""

    talker: str = "GN"
    course_deg: float | None = None
    speed_mps: float | None = None
    mode: str = ""


def _sentence(addr: str, fields: list[str]) -> str:
    body = ",".join([addr, *fields])
    return f"${body}*{calc_checksum(body)}\r\n"


def _fmt_time(t: float | None) -> str:
    if t is None:
        return ""
    cs = round(t * 100.0) % 8_640_000  # centiseconds, wrapped at midnight
    h, rem = divmod(cs, 360_000)
    m, rem = divmod(rem, 6000)
    return f"{h:02d}{m:02d}{rem // 100:02d}.{rem % 100:02d}"


def _fmt_angle(value: float | None, width: int, pos: str, neg: str) -> list[str]:
    if value is None:
        return ["", ""]
    # 8 decimals of a minute is 0.02 mm: quantisation far below RTK noise.
    total = round(abs(value) * 60.0, 8)
    deg, minutes = divmod(total, 60.0)
    return [f"{int(deg):0{width}d}{minutes:011.8f}", pos if value >= 0 else neg]


def _fmt(value: float | None, fmt: str) -> str:
    return "" if value is None or not math.isfinite(value) else format(value, fmt)


def format_gga(g: Gga) -> str:
    """The GGA sentence for ``g``, with checksum and CR/LF."""
    return _sentence(
        f"{g.talker}GGA",
        [
            _fmt_time(g.time_s),
            *_fmt_angle(g.lat_deg, 2, "N", "S"),
            *_fmt_angle(g.lon_deg, 3, "E", "W"),
            str(int(g.quality)),
            f"{g.num_sats:02d}",
            _fmt(g.hdop, ".2f"),
            _fmt(g.alt_msl_m, ".4f"),
            "M",
            _fmt(g.geoid_sep_m, ".4f"),
            "M",
            _fmt(g.diff_age_s, ".1f"),
            "" if g.base_id is None else f"{g.base_id:04d}",
        ],
    )


def format_rmc(r: Rmc, nav_status: bool = True) -> str:
    """The RMC sentence for ``r``: NMEA 4.10 form (nav status ``V``), or with
    ``nav_status=False`` the NMEA 2.3 form that ends at the mode letter (RTKLIB and
    Emlid Reach receivers send that one)."""
    spd = None if r.speed_mps is None else r.speed_mps / KNOT_MPS
    fields = [
        _fmt_time(r.time_s),
        "A" if r.valid else "V",
        *_fmt_angle(r.lat_deg, 2, "N", "S"),
        *_fmt_angle(r.lon_deg, 3, "E", "W"),
        _fmt(spd, ".4f"),
        _fmt(r.course_deg, ".3f"),
        "" if r.date is None else r.date.strftime("%d%m%y"),
        "",
        "",
        r.mode,
        "V",
    ]
    return _sentence(f"{r.talker}RMC", fields if nav_status else fields[:-1])


def format_vtg(v: Vtg) -> str:
    """The VTG sentence (NMEA 2.3 form, with the mode letter) for ``v``: true course,
    no magnetic course, speed in knots and km/h."""
    knots = None if v.speed_mps is None else v.speed_mps / KNOT_MPS
    kmh = None if v.speed_mps is None else v.speed_mps * 3.6
    return _sentence(
        f"{v.talker}VTG",
        [
            _fmt(v.course_deg, ".3f"),
            "T",
            "",
            "M",
            _fmt(knots, ".4f"),
            "N",
            _fmt(kmh, ".4f"),
            "K",
            v.mode,
        ],
    )


def format_gst(s: Gst) -> str:
    """The GST sentence for ``s`` (metres with 4 decimals)."""
    return _sentence(
        f"{s.talker}GST",
        [
            _fmt_time(s.time_s),
            _fmt(s.rms_m, ".4f"),
            _fmt(s.std_major_m, ".4f"),
            _fmt(s.std_minor_m, ".4f"),
            _fmt(s.orient_deg, ".2f"),
            _fmt(s.std_lat_m, ".4f"),
            _fmt(s.std_lon_m, ".4f"),
            _fmt(s.std_alt_m, ".4f"),
        ],
    )
