"""The localization filter's invariants, over any sequence of measurements Hypothesis
finds: whatever it is fed (sane or absurd, in order or not), it never raises, its
state stays finite with the heading wrapped, its covariance stays symmetric and
positive semi-definite, and a measurement it fuses never makes it less sure of the
states that measurement observes."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from services.nav.ekf import EkfConfig, Localizer

finite = st.floats(-1e3, 1e3, allow_nan=False)
anything = st.one_of(finite, st.sampled_from([math.nan, math.inf, -math.inf, 0.0, 1e12]))
variance = st.one_of(st.floats(1e-8, 10.0), st.sampled_from([0.0, -1.0, math.nan, math.inf]))
dt = st.floats(0.0, 2.0)

odometry = st.tuples(st.just("odometry"), dt, anything, anything, variance, variance, st.booleans())
antenna = st.tuples(
    st.just("antenna"), dt, anything, anything, variance, st.sampled_from([(0.4, 0.0), (-0.5, 0.1)])
)
heading = st.tuples(st.just("heading"), dt, anything, st.one_of(st.floats(1e-4, 1.0), variance))
height = st.tuples(st.just("height"), dt, anything, variance)
past = st.floats(-20.0, 0.0)
stale = st.tuples(st.just("stale"), past, finite, finite, variance, st.just((0.0, 0.0)))
steps = st.lists(st.one_of(odometry, antenna, heading, height, stale), min_size=1, max_size=60)

# the states a measurement kind observes: odometry v and w, an antenna x and y, the
# compass the heading
OBSERVED = {"odometry": (3, 4), "antenna": (0, 1), "heading": (2,)}


def feed(loc: Localizer, t: float, m: tuple) -> tuple[float, bool]:
    """Apply one measurement at its time (``stale``: an antenna fix stamped in the
    past); the new time and whether the filter fused it."""
    kind = m[0]
    when = t + m[1]  # a stale fix's offset is negative
    t = max(t, when)
    if kind == "odometry":
        return t, loc.update_odometry(when, m[2], m[3], m[4], m[5], still=m[6])
    if kind in ("antenna", "stale"):
        with np.errstate(invalid="ignore"):  # inf x 0 off the diagonal: an absurd fix
            cov = np.eye(2) * m[4]
        return t, loc.update_antenna(when, np.array([m[2], m[3]]), cov, m[5])
    if kind == "heading":
        return t, loc.update_heading(when, m[2], m[3])
    return t, loc.update_height(when, m[2], m[3])


def healthy(loc: Localizer) -> None:
    x, p = loc.x, loc.P
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(p))
    assert -math.pi <= x[2] < math.pi
    np.testing.assert_allclose(p, p.T, atol=1e-9)
    assert np.linalg.eigvalsh(0.5 * (p + p.T)).min() >= -1e-9


@given(steps)
def test_any_sequence_leaves_a_finite_filter_with_a_proper_covariance(seq: list[tuple]) -> None:
    loc = Localizer(EkfConfig())
    t = 0.0
    for m in seq:
        t, _ = feed(loc, t, m)
        healthy(loc)


small = st.floats(-0.05, 0.05)
sane_var = st.floats(1e-6, 1.0)
# a measurement the gate lets through: near what the filter believes
sane = st.one_of(
    st.tuples(st.just("odometry"), st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), sane_var, sane_var),
    st.tuples(st.just("antenna"), small, small, st.floats(1e-6, 0.01)),
    st.tuples(st.just("heading"), small, st.floats(1e-3, 0.2)),
)


def started() -> Localizer:
    """A filter localized at (1, 2), heading 0.3 rad."""
    loc = Localizer(EkfConfig())
    for k in range(5):
        loc.update_heading(0.1 * k, 0.3, 0.01)
        loc.update_antenna(0.1 * k, np.array([1.0, 2.0]), np.eye(2) * 1e-4, (0.0, 0.0))
    assert loc.initialized
    return loc


@given(steps, sane, dt)
def test_a_fused_measurement_never_adds_doubt_on_what_it_observes(
    seq: list[tuple], last: tuple, wait: float
) -> None:
    loc = started()
    t = 0.5
    for m in seq:
        t, _ = feed(loc, t, m)
    t += wait
    if not loc.initialized:
        return  # the sequence reset it: nothing believed to be sure of
    # the prediction to the measurement's time is the filter's own doing: compare the
    # update alone, on the filter predicted to that time
    loc.predict(t)
    before, resets, x = np.diag(loc.P).copy(), loc.resets, loc.x.copy()
    kind = last[0]
    if kind == "odometry":
        fused = loc.update_odometry(t, last[1], last[2], last[3], last[4])
    elif kind == "antenna":
        xy = x[:2] + np.array([last[1], last[2]])
        fused = loc.update_antenna(t, xy, np.eye(2) * last[3], (0.0, 0.0))
    else:
        fused = loc.update_heading(t, float(x[2]) + last[1], last[2])
    healthy(loc)
    if fused and loc.resets == resets:
        after = np.diag(loc.P)
        for i in OBSERVED[kind]:
            assert after[i] <= before[i] * (1 + 1e-9) + 1e-15, (kind, i, before, after)
