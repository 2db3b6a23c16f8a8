"""RTK error model: configured noise levels, time correlation, Markov chain."""

from __future__ import annotations

import msgspec
import numpy as np
import pytest

from services.gnss.nmea import FixQuality
from services.gnss.rtk_model import (
    STATES,
    RtkErrorModel,
    RtkModelConfig,
    StateNoise,
    sigma_enu,
    stationary_distribution,
)

ALWAYS_FIX = [[0.0] * 4 for _ in range(4)]


def run(cfg: RtkModelConfig, n: int, dt: float = 0.1, seed: int = 1) -> list:
    model = RtkErrorModel(cfg, np.random.default_rng(seed))
    return [model.step(dt) for _ in range(n)]


def test_defaults_follow_reach_m2_datasheet() -> None:
    cfg = RtkModelConfig()
    sig = sigma_enu(cfg.fix, 400.0)
    np.testing.assert_allclose(sig, [0.007 + 0.0004, 0.007 + 0.0004, 0.014 + 0.0004])
    pi = stationary_distribution(cfg)
    assert pi[FixQuality.FIX] > 0.9
    assert sum(pi.values()) == pytest.approx(1.0)


def test_fix_noise_has_the_configured_sigma() -> None:
    cfg = RtkModelConfig(rates_per_s=ALWAYS_FIX, baseline_m=0.0)
    errs = np.array([s.error_enu_m for s in run(cfg, 60_000)])
    # 6000 s with a 2 s correlation time: ~1500 independent samples, so ~2 % spread.
    np.testing.assert_allclose(errs.std(axis=0), [0.007, 0.007, 0.014], rtol=0.08)
    np.testing.assert_allclose(errs.mean(axis=0), 0.0, atol=0.002)


def test_consecutive_fixes_are_correlated() -> None:
    cfg = RtkModelConfig(rates_per_s=ALWAYS_FIX)
    e = np.array([s.error_enu_m[0] for s in run(cfg, 20_000)])
    lag1 = np.corrcoef(e[:-1], e[1:])[0, 1]
    assert lag1 == pytest.approx(np.exp(-0.1 / cfg.fix.correlation_time_s), abs=0.02)


def test_state_occupancy_matches_the_chain() -> None:
    cfg = RtkModelConfig()
    samples = run(cfg, 60_000, dt=0.5, seed=3)  # 30000 s: ~50 FIX episodes
    frac_fix = sum(s.state == FixQuality.FIX for s in samples) / len(samples)
    assert frac_fix == pytest.approx(stationary_distribution(cfg)[FixQuality.FIX], abs=0.03)
    assert {s.state for s in samples} <= set(STATES)
    for s in samples:
        assert (s.error_enu_m is None) == (s.state == FixQuality.NO_FIX)


def test_float_is_noisier_than_fix_and_no_fix_has_no_position() -> None:
    only = [[0.0] * 4 for _ in range(4)]
    cfg = RtkModelConfig(rates_per_s=only, initial_state=FixQuality.FLOAT)
    errs = np.array([s.error_enu_m for s in run(cfg, 20_000)])
    assert errs[:, 0].std() > 0.1
    cfg = RtkModelConfig(rates_per_s=only, initial_state=FixQuality.NO_FIX)
    assert all(s.error_enu_m is None and s.sigma_enu_m is None for s in run(cfg, 10))


def test_same_seed_same_samples() -> None:
    assert run(RtkModelConfig(), 500, seed=7) == run(RtkModelConfig(), 500, seed=7)


def test_config_round_trips_and_rejects_bad_input() -> None:
    cfg = RtkModelConfig(fix=StateNoise(h_const_m=0.01, v_const_m=0.02))
    assert msgspec.json.decode(msgspec.json.encode(cfg), type=RtkModelConfig) == cfg
    with pytest.raises(msgspec.ValidationError, match="4x4"):
        msgspec.json.decode(b'{"rates_per_s": [[0.0]]}', type=RtkModelConfig)
    with pytest.raises(msgspec.ValidationError, match="unknown field"):
        msgspec.json.decode(b'{"fixx": {}}', type=RtkModelConfig)
    with pytest.raises(ValueError, match="dt_s"):
        RtkErrorModel(RtkModelConfig(), np.random.default_rng(0)).step(0.0)


def test_under_the_crop_the_fix_is_noisier_and_lost_more_often() -> None:
    from services.gnss.rtk_model import CanopyConfig

    canopy = CanopyConfig(noise_gain=2.0, float_gain=10.0)
    cfg = RtkModelConfig(rates_per_s=ALWAYS_FIX, baseline_m=0.0, canopy=canopy)
    model = RtkErrorModel(cfg, np.random.default_rng(2))
    half = [model.step(0.1, blocked=0.5) for _ in range(60_000)]
    errs = np.array([s.error_enu_m for s in half])
    # half the sky hidden: 1 + 2 x 0.5 = twice the open-sky sigma, stated as such
    np.testing.assert_allclose(errs.std(axis=0), [0.014, 0.014, 0.028], rtol=0.08)
    assert half[-1].sigma_enu_m == pytest.approx((0.014, 0.014, 0.028))
    # the fix is left 1 + 10 x blocked times as often: the time in FIX falls with it
    lossy = RtkModelConfig(canopy=canopy)
    for blocked in (0.0, 0.5):
        model = RtkErrorModel(lossy, np.random.default_rng(3))
        states = [model.step(0.5, blocked=blocked).state for _ in range(60_000)]
        fix = sum(s == FixQuality.FIX for s in states) / len(states)
        q = np.array(lossy.rates_per_s, dtype=float)
        q[0] *= 1.0 + 10.0 * blocked
        expect = stationary_distribution(msgspec.structs.replace(lossy, rates_per_s=q.tolist()))[
            FixQuality.FIX
        ]
        assert fix == pytest.approx(expect, abs=0.03), blocked
    # absurd values are taken as the open sky or a closed one, never a crash
    assert RtkErrorModel(cfg, np.random.default_rng(0)).step(0.1, blocked=float("nan")).state
