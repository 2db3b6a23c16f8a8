"""Simulated FARO Focus S70 scans (written as E57 by :func:`common.pointcloud.write_e57`).

Angles: the scanner sweeps elevation (0 = horizontal, up positive) from
``vertical_start_deg`` to ``vertical_end_deg`` and azimuth (counter-clockwise from
the scanner's +x) from ``horizontal_start_deg`` over ``horizontal_end_deg``; row
``i`` is elevation ``vertical_start_deg + i * step_deg``, column ``j`` azimuth
``horizontal_start_deg + j * step_deg``. Points come back in the ``scanner`` frame
(x forward, z up at the optical centre).

Error model (:class:`FaroNoise`), from FARO's Focus S70 tech sheet as we read it
(the sheet itself could not be retrieved in this environment; values as commonly
published for the Focus S series): ranging noise (1 sigma, raw data) 0.3 mm at 10 and
25 m on 90 % reflectivity, 0.4 mm at 10 m and 0.5 mm at 25 m on 10 %; ranging error
+-1 mm (a systematic offset, drawn once per scan); angular accuracy 19 arcsec per
axis; range 0.6-70 m on a 90 % target. The noise figures are fitted by
``sigma^2 = a^2 + c * r * (0.1 / rho)^1.5`` (a = 0.3 mm, c = 0.0067 mm^2/m), which
reproduces all four datasheet points within 0.01 mm; ``rho`` is the effective
reflectivity (class reflectivity times the cosine of the incidence angle, Lambertian),
and returns weaker than a 90 % target at 70 m (``r > 70 m * sqrt(rho / 0.9)``) are
dropped. Reflectivities at the scanner's 1550 nm are assumptions: dry soil 0.35, leaves
0.25 (water absorbs there), stems 0.3, white target spheres 0.85, aluminium 0.55.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Annotated

import msgspec
import numpy as np

from common.arrays import F32, F64, I32, U8
from common.field import ScannerModel
from common.messages.core import NonNegative, Positive
from services.sim.scene import GROUND, LEAF_HIT, OBSTACLE, PLOT, POLE, SPHERE, STEM_HIT, Scene

ARCSEC = math.pi / (180 * 3600)


class ScanSettings(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Scan window and resolution (degrees, metres); defaults are the paper's FARO
    settings ("TLS automation experiments"): -60..90 deg vertical, 0..360 deg
    horizontal, 0.36 deg steps, 0.6-70 m."""

    vertical_start_deg: Annotated[float, msgspec.Meta(ge=-90, le=90)] = -60.0
    """The lowest elevation swept (deg; 0 horizontal, up positive)."""
    vertical_end_deg: Annotated[float, msgspec.Meta(ge=-90, le=90)] = 90.0
    """The highest elevation swept (deg)."""
    horizontal_start_deg: Annotated[float, msgspec.Meta(ge=-360, le=360)] = 0.0
    """The first azimuth swept (deg, counter-clockwise from the scanner's +x)."""
    horizontal_end_deg: Annotated[float, msgspec.Meta(ge=-360, le=720)] = 360.0
    """The last azimuth swept (deg)."""
    step_deg: Annotated[float, msgspec.Meta(gt=0.005, le=45)] = 0.36
    """The angular step between rows and between columns (deg)."""
    min_range: NonNegative = 0.6
    """The shortest range measured (m)."""
    max_range: Positive = 70.0
    """The longest range measured (m)."""

    @classmethod
    def from_model(cls, m: ScannerModel) -> ScanSettings:
        """The scan window of the planner's scanner model."""
        return cls(
            vertical_start_deg=m.vertical_start_deg,
            vertical_end_deg=m.vertical_end_deg,
            horizontal_start_deg=m.horizontal_start_deg,
            horizontal_end_deg=m.horizontal_end_deg,
            step_deg=m.step_deg,
            min_range=m.min_range,
            max_range=m.max_range,
        )


class FaroNoise(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Range, angle and intensity errors; see the module docstring for sources."""

    noise_floor_mm: NonNegative = 0.3
    """``a`` of the ranging noise ``sigma^2 = a^2 + c * r * (0.1 / rho)^1.5`` (mm)."""
    noise_slope_mm2_per_m: NonNegative = 0.0067
    """``c`` of the ranging noise (mm²/m)."""
    range_bias_mm: NonNegative = 1.0
    """The ranging error's bound (mm): a systematic offset drawn uniformly within it,
    once per scan."""
    angle_sigma_arcsec: NonNegative = 19.0
    """The angular accuracy per axis (arcsec, 1-sigma)."""
    reflectivity_range_limit: bool = True
    """Drop weak returns as the lidar equation says (beyond 70 m x sqrt(rho / 0.9));
    false: keep all up to ``max_range``."""
    intensity_noise: NonNegative = 0.03
    """The intensity's relative noise (1-sigma)."""


REFLECTIVITY = {
    GROUND: 0.35,
    LEAF_HIT: 0.25,
    STEM_HIT: 0.3,
    SPHERE: 0.85,
    POLE: 0.55,
    OBSTACLE: 0.5,
    PLOT: 0.25,
}


@dataclasses.dataclass(frozen=True, eq=False)
class Scan:
    """One rendered scan: points (N, 3) float64 in the ``scanner`` frame (m),
    intensity (N,) in [0, 1], row/column indices (N,), surface labels (N,) (truth,
    see :data:`services.sim.scene.LABEL_NAMES`), and the grid shape (rows, cols)."""

    points: F64
    intensity: F32
    row: I32
    col: I32
    label: U8
    shape: tuple[int, int]


def scan_grid(s: ScanSettings) -> tuple[F64, F64]:
    """Elevations (rows,) and azimuths (cols,) in radians; raises ValueError for an
    empty window."""
    nv = math.floor((s.vertical_end_deg - s.vertical_start_deg) / s.step_deg + 1e-9) + 1
    span = s.horizontal_end_deg - s.horizontal_start_deg
    # a full turn does not repeat its first column
    nh = math.floor(span / s.step_deg + 1e-9) + (0 if abs(span - 360.0) < 1e-9 else 1)
    if nv < 1 or nh < 1 or s.max_range <= s.min_range:
        raise ValueError(f"scan settings give an empty scan: {s}")
    el = np.radians(s.vertical_start_deg + np.arange(nv) * s.step_deg)
    az = np.radians(s.horizontal_start_deg + np.arange(nh) * s.step_deg)
    return el, az


def _dirs(el: F64, az: F64) -> F64:
    ce = np.cos(el)
    return np.stack([ce * np.cos(az), ce * np.sin(az), np.sin(el)], axis=-1)


def range_sigma(r: F64, rho: F64, noise: FaroNoise) -> F64:
    """1-sigma ranging noise (m) at ranges ``r`` (m) on effective reflectivity ``rho``."""
    rho = np.maximum(rho, 0.01)
    var = noise.noise_floor_mm**2 + noise.noise_slope_mm2_per_m * r * (0.1 / rho) ** 1.5
    out: F64 = np.sqrt(var) * 1e-3
    return out


def render(
    scene: Scene,
    pose: F64,
    settings: ScanSettings,
    rng: np.random.Generator,
    noise: FaroNoise | None = None,
) -> Scan:
    """Scan ``scene`` from the scanner pose ``pose`` (4x4, field <- scanner)."""
    noise = noise or FaroNoise()
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
        raise ValueError(f"pose must be a finite 4x4 transform, got shape {pose.shape}")
    el, az = scan_grid(settings)
    rr, cc = np.meshgrid(np.arange(len(el)), np.arange(len(az)), indexing="ij")
    rows, cols = rr.ravel(), cc.ravel()
    nominal = _dirs(el[rows], az[cols])
    # the mirror points where its encoders do not quite say: cast along the true
    # direction, report along the nominal one
    sa = noise.angle_sigma_arcsec * ARCSEC
    true_dirs = _dirs(
        el[rows] + sa * rng.standard_normal(len(rows)),
        az[cols] + sa * rng.standard_normal(len(rows)),
    )
    rot, origin = pose[:3, :3], pose[:3, 3]
    t, lab, nrm = scene.cast(origin, true_dirs @ rot.T, settings.max_range)
    hit = np.isfinite(t) & (t >= settings.min_range)
    t, lab, nrm = t[hit], lab[hit], nrm[hit]
    d_field = true_dirs[hit] @ rot.T
    cos_inc = np.abs(np.einsum("ij,ij->i", nrm, d_field))
    refl = np.zeros(256)
    for k, v in REFLECTIVITY.items():
        refl[k] = v
    rho = refl[lab] * cos_inc
    keep = np.ones(len(t), dtype=bool)
    if noise.reflectivity_range_limit:
        keep = t <= settings.max_range * np.sqrt(np.maximum(rho, 0.0) / 0.9)
    t, lab, rho = t[keep], lab[keep], rho[keep]
    idx = np.flatnonzero(hit)[keep]
    bias = rng.uniform(-1.0, 1.0) * noise.range_bias_mm * 1e-3
    r = t + bias + range_sigma(t, rho, noise) * rng.standard_normal(len(t))
    pts = nominal[idx] * r[:, None]
    inten = rho * (1.0 + noise.intensity_noise * rng.standard_normal(len(t)))
    return Scan(
        points=pts,
        intensity=np.clip(inten, 0.0, 1.0).astype(np.float32),
        row=rows[idx].astype(np.int32),
        col=cols[idx].astype(np.int32),
        label=lab.astype(np.uint8),
        shape=(len(el), len(az)),
    )
