"""Entry summaries and heritability on simulated designs with known truth."""

from __future__ import annotations

import numpy as np
import pytest

from services.traits.stats import entry_summary, heritability, heritability_anova

S2G, S2E = 0.01, 0.0025


def _trial(n_entries: int, n_reps: int, seed: int, s2g: float = S2G):
    """A randomised complete block trial: value = 0.6 + rep effect + G + E."""
    rng = np.random.default_rng(seed)
    g = rng.normal(0.0, np.sqrt(s2g), n_entries)
    block = np.array([0.0, 0.03, -0.02, 0.01])[:n_reps]
    entries = [f"E{i:03d}" for i in range(n_entries) for _ in range(n_reps)]
    reps: list[int | None] = [j + 1 for _ in range(n_entries) for j in range(n_reps)]
    ei = np.repeat(np.arange(n_entries), n_reps)
    ri = np.tile(np.arange(n_reps), n_entries)
    values = 0.6 + block[ri] + g[ei] + rng.normal(0.0, np.sqrt(S2E), ei.size)
    return entries, reps, values


def test_entry_summary_per_entry_sorted_skipping_empty():
    entries = ["b", "a", "b", "", "a", "b", "c"]
    values = np.array([1.0, 2.0, 3.0, 100.0, 4.0, np.nan, np.nan])
    got = entry_summary(entries, values)
    assert [s.entry for s in got] == ["a", "b", "c"]
    a, b, c = got
    assert (a.n, a.mean, a.min, a.max) == (2, 3.0, 2.0, 4.0)
    assert a.sd == pytest.approx(np.sqrt(2.0))
    assert (b.n, b.mean) == (2, 2.0)
    assert c.n == 0 and np.isnan(c.mean) and np.isnan(c.sd)
    with pytest.raises(ValueError):
        entry_summary(entries[:3], values)


def test_heritability_recovers_known_truth():
    entries, reps, values = _trial(200, 3, seed=11)
    h = heritability(entries, reps, values)
    assert h.ok, h.reason
    # truth: entry-mean 0.01 / (0.01 + 0.0025 / 3) = 0.923; plot basis 0.8. The
    # tolerances pass a correct estimate and fail the other formula's value.
    assert h.h2_mean == pytest.approx(S2G / (S2G + S2E / 3), abs=0.03)
    assert h.h2_plot == pytest.approx(S2G / (S2G + S2E), abs=0.05)
    assert h.sigma2_g == pytest.approx(S2G, rel=0.25)
    assert h.sigma2_e == pytest.approx(S2E, rel=0.15)
    assert h.r_mean == pytest.approx(3.0) and h.n_entries == 200 and h.n_plots == 600
    assert h.model == "REML mixed model: y ~ rep + (1|entry)"


def test_reml_and_anova_agree_on_balanced_data():
    for seed in range(3):
        entries, reps, values = _trial(20, 3, seed=seed)
        reml = heritability(entries, reps, values)
        anova = heritability_anova(entries, reps, values)
        assert reml.ok and anova.ok, (reml.reason, anova.reason)
        assert reml.sigma2_g == pytest.approx(anova.sigma2_g, rel=1e-3, abs=1e-7)
        assert reml.sigma2_e == pytest.approx(anova.sigma2_e, rel=1e-3)
        assert reml.h2_mean == pytest.approx(anova.h2_mean, abs=1e-4)
    # without reps both fit the one-way model
    no_reps: list[int | None] = [None] * len(entries)
    reml = heritability(entries, no_reps, values)
    anova = heritability_anova(entries, no_reps, values)
    assert reml.model == "REML mixed model: y ~ 1 + (1|entry)"
    assert reml.h2_mean == pytest.approx(anova.h2_mean, abs=1e-4)


def test_no_genetic_variance_gives_zero():
    # every entry has the same mean: sigma2_g is 0 at the optimum
    rng = np.random.default_rng(5)
    entries = [f"E{i}" for i in range(15) for _ in range(3)]
    reps: list[int | None] = [1, 2, 3] * 15
    values = np.concatenate([0.5 + rng.permutation([-0.05, 0.0, 0.05]) for _ in range(15)])
    anova = heritability_anova(entries, reps, values)
    assert anova.ok and anova.sigma2_g == 0.0 and anova.h2_mean == 0.0
    reml = heritability(entries, reps, values)
    assert reml.ok, reml.reason
    assert reml.h2_mean < 1e-3 and reml.h2_plot < 1e-3


def test_unbalanced_nan_and_empty_entries():
    entries, reps, values = _trial(20, 3, seed=2)
    values[[0, 4, 8]] = np.nan
    entries = [*entries, "", ""]
    reps = [*reps, None, None]
    values = np.append(values, [9.0, 9.0])
    h = heritability(entries, reps, values)
    assert h.ok and h.n_plots == 57 and h.n_entries == 20
    assert h.r_mean == pytest.approx(20 / (17 / 3 + 3 / 2))
    assert h.model == "REML mixed model: y ~ rep + (1|entry)"
    anova = heritability_anova(entries, reps, values)
    assert not anova.ok and "unbalanced" in anova.reason


def test_too_few_replicated_entries_is_not_ok_and_never_raises():
    h = heritability(["a", "a", "b"], [1, 2, 1], np.array([1.0, 1.1, 2.0]))
    assert not h.ok and "at least 2" in h.reason and np.isnan(h.h2_mean)
    assert not heritability(["a", "b"], [1], np.array([1.0, 2.0])).ok
    assert not heritability([], [], np.array([])).ok
    flat = heritability(["a", "a", "b", "b"], [1, 2, 1, 2], np.ones(4))
    assert not flat.ok and "equal" in flat.reason
    assert not heritability_anova(["a", "b"], [1, 1], np.array([np.nan, 1.0])).ok
