"""From parsed sentences to bus messages: NavSatFix per antenna and the compass
heading in the ``field`` frame. Pure: no I/O."""

from __future__ import annotations

import math

import numpy as np

from common.geo import FieldFrame
from common.messages.core import FIELD_FRAME
from common.messages.gnss import FixType, GnssHeading, NavSatFix
from services.gnss.compass import Compass, CompassError, compass_heading
from services.gnss.nmea import Gga, Gst


class FixBuilder:
    """Turns one antenna's GGA (+ GST) stream into NavSatFix messages.

    Receivers send GST before or after GGA in an epoch (a Reach M2 sends it after);
    the covariance uses the GST of the same epoch when it came first, else the newest
    one within 1.5 s, else the fallback sigma for the fix type. An older GST is not
    used across a change of fix type: the first RTK-float fix after a fixed one must
    not carry the fixed solution's millimetres.
    """

    def __init__(self, antenna: int, fallback_sigma_m: dict[str, float]) -> None:
        self.antenna = antenna
        self.fallback = fallback_sigma_m
        self._gst: Gst | None = None
        self._gst_quality: FixType | None = None  # of the GGA it followed; None: unknown
        self._last_gga: tuple[float | None, FixType] | None = None

    def on_gst(self, gst: Gst) -> None:
        self._gst = gst
        last = self._last_gga
        self._gst_quality = last[1] if last is not None and last[0] == gst.time_s else None

    def sigmas(self, gga: Gga) -> tuple[float, float, float]:
        g = self._gst
        if (
            g is not None
            and g.time_s is not None
            and gga.time_s is not None
            and abs(((gga.time_s - g.time_s + 43200) % 86400) - 43200) <= 1.5
            and g.std_lat_m is not None
            and g.std_lon_m is not None
            and (g.time_s == gga.time_s or self._gst_quality in (None, gga.quality))
        ):
            alt = g.std_alt_m if g.std_alt_m is not None else 2 * g.std_lat_m
            return g.std_lon_m, g.std_lat_m, alt
        s = self.fallback.get(FixType(gga.quality).name, 10.0)
        return s, s, 2 * s

    def on_gga(self, gga: Gga, stamp_ns: int) -> NavSatFix | None:
        """The fix for this GGA, or None when the receiver has no position."""
        self._last_gga = (gga.time_s, FixType(gga.quality))
        if gga.lat_deg is None or gga.lon_deg is None or gga.quality == FixType.NO_FIX:
            return None
        se, sn, su = self.sigmas(gga)
        cov = (se * se, 0.0, 0.0, 0.0, sn * sn, 0.0, 0.0, 0.0, su * su)
        return NavSatFix(
            stamp_ns=stamp_ns,
            frame_id=f"gnss_{self.antenna}",
            antenna=self.antenna,
            latitude=gga.lat_deg,
            longitude=gga.lon_deg,
            altitude=(gga.alt_msl_m or 0.0) + (gga.geoid_sep_m or 0.0),
            fix_type=FixType(gga.quality),
            position_covariance=cov,
            num_satellites=gga.num_sats,
            hdop=gga.hdop or 0.0,
        )


def fix_in_field(fix: NavSatFix, frame: FieldFrame) -> tuple[np.ndarray, np.ndarray]:
    """Position (x, y, z) in the ``field`` frame and its 3x3 covariance there."""
    x, y, z = frame.wgs84_to_field(fix.latitude, fix.longitude, fix.altitude)
    return np.array([float(x), float(y), float(z)]), frame.enu_cov_to_field(fix.position_covariance)


def heading(f1: NavSatFix, f2: NavSatFix, frame: FieldFrame, compass: Compass) -> GnssHeading:
    """The compass heading from a same-epoch pair of fixes (paper eq. 2).

    Valid only when both antennas have an RTK fix and the measured baseline matches
    the mounted one; otherwise ``valid`` is false and ``yaw_sd`` is pi.
    """
    p1, c1 = fix_in_field(f1, frame)
    p2, c2 = fix_in_field(f2, frame)
    base = float(np.linalg.norm(p2[:2] - p1[:2]))
    stamp = max(f1.stamp_ns, f2.stamp_ns)
    both_fixed = f1.fix_type == FixType.FIX and f2.fix_type == FixType.FIX
    try:
        h = compass_heading(p1, p2, c1, c2, compass)
    except CompassError:
        yaw = math.atan2(p2[1] - p1[1], p2[0] - p1[0])
        return GnssHeading(
            stamp_ns=stamp,
            frame_id=FIELD_FRAME,
            yaw=yaw,
            yaw_sd=math.pi,
            baseline_m=base,
            valid=False,
        )
    return GnssHeading(
        stamp_ns=stamp,
        frame_id=FIELD_FRAME,
        yaw=h.yaw_rad,
        yaw_sd=h.yaw_std_rad if both_fixed else math.pi,
        baseline_m=h.baseline_m,
        valid=both_fixed,
    )
