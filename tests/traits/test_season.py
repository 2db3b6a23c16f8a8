"""Season functions on simulated surveys with known truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from services.traits.growth_figure import growth_figure
from services.traits.season import (
    fit_all,
    fit_logistic,
    growth,
    growth_rate,
    vertical_offset,
)

K, R, T0 = 0.8, 0.15, 40.0


def _curve(t: np.ndarray) -> np.ndarray:
    return K / (1.0 + np.exp(-R * (t - T0)))


def _grounds(shift: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:80, 0:60] * 0.1
    terrain = 0.05 * np.sin(xx / 2.0) + 0.02 * yy
    ref = terrain + rng.normal(0.0, 0.005, terrain.shape)
    new = terrain + shift + rng.normal(0.0, 0.005, terrain.shape)
    stable = np.zeros(terrain.shape, dtype=bool)
    stable[:, ::6] = True  # lanes every sixth column
    stable[:5, :] = True  # a headland
    # plant cells: the later date's "ground" there is canopy, which must not count
    new[~stable] += 0.4
    ref[3, ::6] = np.nan
    new[:2, :] = np.nan
    return ref, new, stable


def test_offset_recovers_shift_and_ignores_plant_cells():
    ref, new, stable = _grounds(0.03)
    off = vertical_offset(ref, new, stable)
    assert off.median_m == pytest.approx(0.03, abs=0.002)
    assert off.sigma_m == pytest.approx(0.005 * np.sqrt(2.0), rel=0.2)
    both = stable & np.isfinite(ref) & np.isfinite(new)
    assert off.n_cells == int(both.sum())
    assert off.exceeds
    assert 0.0 < off.se_m < 0.001


def test_offset_below_tolerance_is_agreement():
    ref, new, stable = _grounds(0.003, seed=1)
    off = vertical_offset(ref, new, stable)
    assert not off.exceeds
    assert off.tolerance_m == 0.01


def test_offset_fits_the_tilt_between_two_registrations():
    yy, xx = np.mgrid[0:80, 0:60] * 0.1
    # no offset on average, but 1.5 cm per 6 m along x: the ends differ by +-4.5 mm
    tilt = 0.0025 * (xx - xx.mean())
    ref, new, stable = _grounds(0.0, seed=2)
    new = new + tilt
    flat = vertical_offset(ref, new, stable)
    assert not flat.exceeds and flat.plane is None  # no cell positions: no tilt
    off = vertical_offset(ref, new, stable, tolerance_m=0.004, centres=(xx, yy))
    assert off.plane is not None and off.plane[1] == pytest.approx(0.0025, abs=0.0003)
    assert abs(off.plane[2]) < 0.0003 and off.exceeds  # the ends are beyond 4 mm
    at = off.at(np.array([0.0, 5.9]), np.array([1.0, 1.0]))
    assert at == pytest.approx(tilt[10, [0, 59]], abs=0.002)


def test_offset_without_common_stable_ground_raises():
    ref, new, stable = _grounds(0.0)
    new[stable] = np.nan
    with pytest.raises(ValueError, match="same field"):
        vertical_offset(ref, new, stable)
    with pytest.raises(ValueError, match="shape"):
        vertical_offset(ref, new[1:], stable)


def test_growth_is_the_difference_and_rate_per_day():
    days = np.array([10.0, 20.0, 40.0])
    values = np.array([[0.1, 0.2], [0.3, np.nan], [0.7, 0.5]])
    g = growth(values, days)
    assert g.shape == (2, 2)
    np.testing.assert_allclose(g[:, 0], [0.2, 0.4])
    assert np.isnan(g[:, 1]).all()
    np.testing.assert_allclose(growth_rate(values, days)[:, 0], [0.02, 0.02])
    with pytest.raises(ValueError, match="increase"):
        growth(values, np.array([10.0, 10.0, 40.0]))
    with pytest.raises(ValueError, match="dates, plots"):
        growth(values, days[:2])


def test_logistic_recovers_parameters_from_five_noisy_dates():
    days = np.array([10.0, 25.0, 40.0, 55.0, 75.0])
    rng = np.random.default_rng(3)
    fit = fit_logistic(days, _curve(days) + rng.normal(0.0, 0.01, days.size))
    assert fit.ok, fit.reason
    assert fit.k == pytest.approx(K, abs=0.04)
    assert fit.r == pytest.approx(R, abs=0.04)
    assert fit.t0 == pytest.approx(T0, abs=3.0)
    assert fit.n == 5 and fit.dof == 2
    assert fit.rmse < 0.02
    assert fit.reason == ""
    exact = fit_logistic(days, _curve(days))
    assert (exact.k, exact.r, exact.t0) == pytest.approx((K, R, T0), rel=1e-4)
    np.testing.assert_allclose(exact.predict(days), _curve(days), atol=1e-6)


def test_logistic_too_few_dates_is_not_ok_and_never_raises():
    two = fit_logistic(np.array([10.0, 30.0]), np.array([0.1, 0.5]))
    assert not two.ok and "at least 3" in two.reason and np.isnan(two.k)
    nan = fit_logistic(np.array([10.0, 30.0, 50.0]), np.array([0.1, np.nan, 0.6]))
    assert not nan.ok and nan.n == 2
    assert not fit_logistic(np.full(4, np.nan), np.full(4, np.nan)).ok
    assert not fit_logistic(np.arange(4.0), np.zeros(4)).ok
    assert not fit_logistic(np.arange(4.0), np.arange(3.0)).ok


def test_logistic_three_dates_fit_exactly_without_residual_dof():
    days = np.array([25.0, 40.0, 60.0])
    fit = fit_logistic(days, _curve(days))
    assert fit.ok
    assert fit.dof == 0 and "no residual degrees of freedom" in fit.reason
    assert fit.rmse < 1e-6


def test_logistic_not_levelled_off_is_not_ok():
    days = np.array([0.0, 5.0, 10.0, 15.0])
    fit = fit_logistic(days, 0.01 * np.exp(0.1 * days))  # still exponential
    assert not fit.ok and "levelled off" in fit.reason


def test_fit_all_one_fit_per_plot():
    days = np.array([10.0, 25.0, 40.0, 55.0, 75.0])
    values = np.column_stack([_curve(days), 0.5 * _curve(days), np.full(5, np.nan)])
    fits = fit_all(days, values)
    assert [f.ok for f in fits] == [True, True, False]
    assert fits[1].k == pytest.approx(K / 2, rel=1e-3)


def test_growth_figure_is_written_atomically(tmp_path: Path):
    days = np.array([10.0, 25.0, 40.0])
    entries = ["A", "A", "B", "B", ""]
    values = np.outer(_curve(days), [1.0, 0.9, 0.5, 0.6, 0.7])
    values[1, 1] = np.nan
    out = tmp_path / "growth_height.png"
    growth_figure(out, ["05-01", "05-16", "05-31"], days, values, entries, "height", "m")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == [out.name]
    growth_figure(out, ["a", "b", "c"], np.full(3, np.nan), values, entries, "cover", "1")
    with pytest.raises(ValueError, match="dates, plots"):
        growth_figure(out, ["a", "b"], days, values, entries, "height", "m")
