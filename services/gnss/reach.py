"""A simulated Emlid Reach M2 (pure: antenna truth in, NMEA text out, no I/O).

One code path for every simulated receiver: the ``sim`` backend
(:class:`services.gnss.receiver.SimReceiver`, over Zenoh) and the wire simulator
(:mod:`services.gnss.sim.reach`, over TCP and a serial pseudo-terminal) both call
:meth:`ReachM2.epoch`.

What a Reach M2 sends per epoch on its NMEA position output, as this module writes it:
``RMC, GGA, GST, VTG`` with the ``GN`` talker (``GP`` selectable in ReachView).
Sources: Emlid's Reach M2 docs, "Position output" (NMEA 0183: GGA, GSA, GST, GSV,
RMC, VTG, ZDA; talker GP or GN; output rate settable; over serial, TCP or Bluetooth),
the Reach RS2/RS3 "NMEA specification" pages (GN talker by default), and a raw Reach
log posted in rpng/reach_ros_node issue #2, which shows the order
``RMC, GGA, (GSA, GSV at 1 Hz), GST, VTG`` and the layouts: RMC in the NMEA 2.3 form
(ends at the mode letter, no nav status), course left empty when standing still, GST
with the error-ellipse fields (major, minor, orientation) empty. GSA/GSV/ZDA are
left out: the gnss service has no use for satellite lists.
"""

from __future__ import annotations

import datetime as dt
import math

import msgspec
import numpy as np

from common.clock import NS
from common.geo import FieldFrame
from common.messages.sim import SimAntennas
from services.gnss.nmea import FixQuality, Gga, Gst, Rmc
from services.gnss.nmea_format import Vtg, format_gga, format_gst, format_rmc, format_vtg
from services.gnss.rtk_model import STATES, RtkErrorModel, RtkModelConfig, RtkSample

# Below this the course over ground is noise (Reach leaves the field empty at rest).
MIN_COURSE_SPEED_MPS = 0.1
# NMEA 2.3 mode letters per solution state.
_MODE = {
    FixQuality.FIX: "R",
    FixQuality.FLOAT: "F",
    FixQuality.DGPS: "D",
    FixQuality.SINGLE: "A",
    FixQuality.NO_FIX: "N",
}


class ReachM2:
    """One simulated Reach M2 rover for antenna ``antenna`` (1 or 2).

    Its errors come from :class:`RtkErrorModel` seeded by ``(seed, antenna)``. It
    honours the faults the simulator injects (fields of :class:`SimAntennas`): an
    outage sends nothing; a forced float reports RTK float (quality 5) with the float
    noise of a second RTK model locked in FLOAT; a multipath offset is added to the
    reported position with the quality unchanged. Both models step every epoch
    whatever the faults, on their own generators, so the receiver's noise outside a
    fault is the same with or without it. Velocity (RMC, VTG) is the truth's, as a
    receiver's Doppler velocity is blind to multipath in position."""

    def __init__(
        self, rtk: RtkModelConfig, seed: int, antenna: int, frame: FieldFrame, talker: str = "GN"
    ) -> None:
        self.antenna = antenna
        self.talker = talker
        self._frame = frame
        self._model = RtkErrorModel(rtk, np.random.default_rng([seed, antenna]))
        no_jumps = [[0.0] * len(STATES) for _ in STATES]
        locked = msgspec.structs.replace(rtk, initial_state=FixQuality.FLOAT, rates_per_s=no_jumps)
        self._float = RtkErrorModel(locked, np.random.default_rng([seed, antenna, 5]))
        self._last: tuple[int, float, float] | None = None  # stamp_ns, east, north of truth

    def epoch(self, msg: SimAntennas) -> str:
        """The sentences for one simulator epoch (``""`` during an outage). Steps the
        error models by the time since the previous epoch (sim time)."""
        one = self.antenna == 1
        p = msg.p1 if one else msg.p2
        e, n = (float(v) for v in self._frame.field_to_map(p[0], p[1]))
        dt_s, vel = 0.1, (0.0, 0.0)
        if self._last is not None:
            dt_s = max(1e-3, (msg.stamp_ns - self._last[0]) / NS)
            vel = ((e - self._last[1]) / dt_s, (n - self._last[2]) / dt_s)
        self._last = (msg.stamp_ns, e, n)
        sample = self._model.step(dt_s, blocked=msg.blocked1 if one else msg.blocked2)
        floating = self._float.step(dt_s)
        if msg.outage1 if one else msg.outage2:
            return ""
        if msg.force_float1 if one else msg.force_float2:
            sample = floating
        east, north = msg.offset1 if one else msg.offset2
        if sample.error_enu_m is not None and (east or north):
            de, dn, du = sample.error_enu_m
            sample = msgspec.structs.replace(sample, error_enu_m=(de + east, dn + north, du))
        date = dt.datetime.fromtimestamp(msg.stamp_ns // NS, dt.UTC).date()
        tod = (msg.stamp_ns / NS) % 86400.0
        return receiver_output(self._frame, p, sample, tod, vel, date, self.talker)


def receiver_output(
    frame: FieldFrame,
    truth: tuple[float, float, float],
    sample: RtkSample,
    tod: float,
    vel_en: tuple[float, float] = (0.0, 0.0),
    date: dt.date | None = None,
    talker: str = "GN",
) -> str:
    """What a Reach M2 sends for one epoch (RMC, GGA, GST, VTG) for an antenna truly
    at ``truth`` (field frame, m) moving at ``vel_en`` (east, north, m/s) with the RTK
    model's ``sample`` of error; ``tod`` seconds of the UTC day, ``date`` the UTC
    date (None: left empty). No fix: RMC and GGA without a position."""
    mode, t = _MODE.get(sample.state, "A"), talker
    if sample.error_enu_m is None or sample.sigma_enu_m is None:
        void = Rmc(
            talker=t, time_s=tod, date=date, valid=False, lat_deg=None, lon_deg=None, mode=mode
        )
        q = sample.state
        empty = Gga(talker=t, time_s=tod, lat_deg=None, lon_deg=None, alt_msl_m=None, quality=q)
        return format_rmc(void, nav_status=False) + format_gga(empty)
    err, sig = sample.error_enu_m, sample.sigma_enu_m
    e, n = frame.field_to_map(truth[0], truth[1])
    lat, lon, h = frame.map_to_wgs84(e + err[0], n + err[1], truth[2] + err[2])
    lat, lon = float(lat), float(lon)
    speed = math.hypot(*vel_en)
    course = None
    if speed >= MIN_COURSE_SPEED_MPS:
        course = math.degrees(math.atan2(vel_en[0], vel_en[1])) % 360.0
    rmc = Rmc(
        talker=t,
        time_s=tod,
        date=date,
        valid=True,
        lat_deg=lat,
        lon_deg=lon,
        speed_mps=speed,
        course_deg=course,
        mode=mode,
    )
    gga = Gga(
        talker=t,
        time_s=tod,
        lat_deg=lat,
        lon_deg=lon,
        alt_msl_m=float(h),
        geoid_sep_m=0.0,
        quality=sample.state,
        num_sats=18,
        hdop=0.6,
        diff_age_s=1.0,
    )
    gst = Gst(
        talker=t,
        time_s=tod,
        rms_m=float(np.linalg.norm(sig)),
        std_lat_m=float(sig[1]),
        std_lon_m=float(sig[0]),
        std_alt_m=float(sig[2]),
    )
    vtg = Vtg(talker=t, course_deg=course, speed_mps=speed, mode=mode)
    return format_rmc(rmc, nav_status=False) + format_gga(gga) + format_gst(gst) + format_vtg(vtg)
