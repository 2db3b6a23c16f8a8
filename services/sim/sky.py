"""How much of a GNSS antenna's sky the crop hides: the simulator's input to the
receivers' canopy model (:class:`services.gnss.rtk_model.CanopyConfig`).

The paper's antennas stand 1.1 m above the ground and its mature plants 1.9 m: in an
alley or a row gap the plots rise 0.8 m above the antennas within a metre on both
sides and hide the low satellites across the lane, where on a headland the sky is
open. Per azimuth (``n_azimuths`` of them) the plots' tops set a mask elevation; the
hidden share is that of the sky above the receiver's own elevation mask
(``cutoff_deg``, 15 deg as Reach receivers default to), weighted by solid angle
(satellites taken as evenly spread over the visible sky, a stated simplification).
Plots count as opaque boxes to their full height (a mature canopy is dense to GNSS
signals at L1/L2: leaves are mostly water).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from common.arrays import F64


class SkyMask:
    """The plots of one field (``boxes``: (P, 6) xmin, ymin, zmin, xmax, ymax, zmax,
    field frame, with ``zmax`` the canopy's top)."""

    def __init__(self, boxes: F64, n_azimuths: int = 72, cutoff_deg: float = 15.0) -> None:
        self._lo = np.asarray(boxes, dtype=np.float64)[:, [0, 1]]
        self._hi = np.asarray(boxes, dtype=np.float64)[:, [3, 4]]
        self._top = np.asarray(boxes, dtype=np.float64)[:, 5]
        az = (np.arange(n_azimuths) + 0.5) * (2 * math.pi / n_azimuths)
        self._dir = np.stack([np.cos(az), np.sin(az)], axis=1)  # (A, 2)
        self._sin_cut = math.sin(math.radians(cutoff_deg))
        cut = math.radians(cutoff_deg)
        self._cot_cut = math.cos(cut) / math.sin(cut) if cut > 0 else math.inf
        # the last few antenna positions and their shares: a standing robot asks the
        # same question every epoch (two antennas, so two entries)
        self._memo: dict[tuple[float, float, float], float] = {}

    def blocked(self, p: npt.ArrayLike) -> float:
        """Share (0-1) of the sky above the cutoff hidden from an antenna at ``p``
        (x, y, z in the field frame)."""
        x, y, z = (float(v) for v in np.asarray(p, dtype=np.float64).ravel()[:3])
        key = (x, y, z)
        share = self._memo.get(key)
        if share is None:
            share = self._blocked(x, y, z)
            if len(self._memo) >= 4:
                self._memo.clear()
            self._memo[key] = share
        return share

    def _blocked(self, x: float, y: float, z: float) -> float:
        rise = self._top - z  # (P,) how far each plot's top stands above the antenna
        # a plot further than rise / tan(cutoff) (its box's nearest point) stays below
        # the cutoff along every azimuth, so it cannot change the share: left out
        gap = np.hypot(
            np.maximum(np.maximum(self._lo[:, 0] - x, x - self._hi[:, 0]), 0.0),
            np.maximum(np.maximum(self._lo[:, 1] - y, y - self._hi[:, 1]), 0.0),
        )
        near = (rise > 0.0) & (gap < rise * self._cot_cut)
        if not near.any():
            return 0.0
        lo, hi, rise = self._lo[near], self._hi[near], rise[near]
        # slab method: where each azimuth's horizontal ray enters each box
        d = self._dir[:, None, :]  # (A, 1, 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (lo[None] - (x, y)) / d
            t2 = (hi[None] - (x, y)) / d
        t1 = np.where(np.isnan(t1), -np.inf, t1)  # a ray along a face's own line
        t2 = np.where(np.isnan(t2), np.inf, t2)
        t_in = np.maximum(np.minimum(t1, t2).max(axis=2), 0.0)  # (A, P)
        t_out = np.maximum(t1, t2).min(axis=2)
        hit = t_out >= t_in
        # the mask elevation of a box is that of its nearest edge's top
        sin_el = np.where(hit, rise / np.hypot(rise, t_in), 0.0).max(axis=1)  # (A,)
        share = (sin_el - self._sin_cut) / (1.0 - self._sin_cut)
        return float(np.clip(share, 0.0, 1.0).mean())
