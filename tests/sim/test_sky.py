"""The crop's share of a GNSS antenna's sky, on the ENGR field."""

from __future__ import annotations

import numpy as np
import pytest

from common.field import load_field
from services.sim.sky import SkyMask

_, ENGR = load_field("engr")
MASK = SkyMask(ENGR.plot_boxes)


def test_the_lanes_between_tall_plots_hide_more_sky_than_the_headlands() -> None:
    x_head, x_alley = ENGR.cross_lanes_x[0], ENGR.cross_lanes_x[2]
    y_gap = ENGR.row_lanes_y[3]
    head = MASK.blocked((x_head, 10.0, 1.1))
    alley = MASK.blocked((x_alley, 10.0, 1.1))
    gap = MASK.blocked((12.0, y_gap, 1.1))
    # a 1.5 m alley between 1.9 m plots is narrower than a 2.25 m headland beside
    # them, and a 0.8 m row gap narrower still
    assert 0.0 < head < alley < gap < 1.0
    # an antenna above the canopy, or far from the field, sees the whole sky
    assert MASK.blocked((x_alley, 10.0, 2.5)) == 0.0
    assert MASK.blocked((-50.0, -50.0, 1.1)) == 0.0
    # inside a plot, nothing is seen
    assert MASK.blocked((3.0, 2.0, 1.1)) == pytest.approx(1.0)


def test_a_single_wall_hides_what_its_geometry_says() -> None:
    # an endless wall 1 m high, 1 m away on one side: below 45 deg, half the azimuths
    wall = SkyMask(np.array([[-1e4, 1.0, 0.0, 1e4, 2.0, 1.0]]), n_azimuths=720, cutoff_deg=0.0)
    az = (np.arange(720) + 0.5) * np.pi / 360
    s = np.sin(az)
    sin_el = np.where(s > 0, 1.0 / np.hypot(1.0, 1.0 / np.where(s > 0, s, 1.0)), 0.0)
    assert wall.blocked((0.0, 0.0, 0.0)) == pytest.approx(sin_el.mean(), rel=1e-6)


def _every_plot(mask: SkyMask, x: float, y: float, z: float) -> float:
    """The share with no plot left out (the slab method over them all)."""
    rise = mask._top - z
    d = mask._dir[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (mask._lo[None] - (x, y)) / d
        t2 = (mask._hi[None] - (x, y)) / d
    t1 = np.where(np.isnan(t1), -np.inf, t1)
    t2 = np.where(np.isnan(t2), np.inf, t2)
    t_in = np.maximum(np.minimum(t1, t2).max(axis=2), 0.0)
    hit = (np.maximum(t1, t2).min(axis=2) >= t_in) & (rise > 0)
    sin_el = np.where(hit, rise / np.hypot(rise, t_in), 0.0).max(axis=1)
    share = (sin_el - mask._sin_cut) / (1.0 - mask._sin_cut)
    return float(np.clip(share, 0.0, 1.0).mean())


def test_leaving_out_the_plots_below_the_cutoff_changes_nothing() -> None:
    rng = np.random.default_rng(4)
    lo, hi = ENGR.plot_boxes[:, :2].min(axis=0) - 3, ENGR.plot_boxes[:, 3:5].max(axis=0) + 3
    for _ in range(300):
        x, y = rng.uniform(lo, hi)
        z = rng.uniform(0.5, 2.0)
        fresh = SkyMask(ENGR.plot_boxes)  # no memo
        assert fresh.blocked((x, y, z)) == pytest.approx(_every_plot(fresh, x, y, z), abs=1e-12)
        # asked again (a standing robot), the same answer
        assert fresh.blocked((x, y, z)) == fresh.blocked((x, y, z))
