"""Error model of an RTK rover, for the simulated receiver (pure: a numpy Generator in,
samples out).

Two parts:

- the solution state (FIX, FLOAT, SINGLE, NO_FIX) follows a continuous-time Markov
  chain, so the time spent in each state does not depend on the output rate;
- the position error is a first-order Gauss-Markov process per ENU axis, so
  consecutive 10 Hz fixes wander together instead of being white. Its stationary
  1-sigma is ``const + ppm * baseline`` for the current state, the way receiver
  datasheets state accuracy.

Defaults and their sources:

- FIX: Emlid Reach M2 datasheet, "RTK: H 7 mm + 1 ppm, V 14 mm + 1 ppm". We read
  the horizontal figure as 1-sigma *per horizontal axis* (the conservative reading;
  it makes a 0.95 m dual-antenna compass read about 0.6 deg 1-sigma, paper eq. 2).
- FLOAT: datasheets do not specify it; Emlid's docs describe float as decimetre-level.
  0.25 m H / 0.5 m V with a 30 s correlation time (float ambiguities drift slowly).
- SINGLE: NovAtel OEM7 datasheet, "Single point L1/L2: 1.2 m RMS" horizontal; the
  vertical is taken as twice that, the usual GNSS geometry ratio (VDOP ~ 2 HDOP).
- FIX correlation time 2 s: multipath on a moving rover decorrelates in seconds;
  single-point errors (ionosphere, orbits) in minutes, hence 120 s.
- Transitions: open-sky RTK holds FIX for minutes; re-fix after a loss takes
  seconds to tens of seconds. Mean dwell FIX 600 s, FLOAT 15 s, SINGLE 10 s,
  NO_FIX 3 s; about 96 % of the time in FIX.
- Baseline 400 m: the paper's base station sat ~400 m from the fields.
"""

from __future__ import annotations

import math

import msgspec
import numpy as np
import numpy.typing as npt

from common.messages.core import NonNegative, Positive
from services.gnss.nmea import FixQuality

#: Order of rows and columns in :attr:`RtkModelConfig.rates_per_s`.
STATES: tuple[FixQuality, ...] = (
    FixQuality.FIX,
    FixQuality.FLOAT,
    FixQuality.SINGLE,
    FixQuality.NO_FIX,
)


class StateNoise(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """1-sigma error of one solution state: ``const_m + ppm * 1e-6 * baseline``."""

    h_const_m: NonNegative
    """The horizontal 1-sigma's constant part, per axis (m)."""
    h_ppm: NonNegative = 1.0
    """The horizontal 1-sigma's part proportional to the baseline (ppm)."""
    v_const_m: NonNegative
    """The vertical 1-sigma's constant part (m)."""
    v_ppm: NonNegative = 1.0
    """The vertical 1-sigma's part proportional to the baseline (ppm)."""
    correlation_time_s: Positive = 2.0
    """The correlation time of the error's Gauss-Markov process (s)."""


class CanopyConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """RTK under a crop: a receiver whose sky is ``blocked`` (0-1, the share of the
    sky above its elevation mask the plots hide; the simulator computes it, see
    :mod:`services.sim.sky`) tracks fewer satellites, through leaves and with
    reflections off them. The mechanism is the paper's geometry (antennas at 1.1 m
    among 1.9 m plants)."""

    noise_gain: NonNegative = 8.0
    """The fixed solution's error grows by ``1 + noise_gain x blocked`` (1-sigma and GST
    alike). An assumption, calibrated so that the paper's own navigation reproduces its
    field cross-track errors in our simulator (8: a fix three times as noisy in a 1.5 m
    alley, a quarter of whose sky the plots hide; docs/simulation.md)."""
    float_gain: NonNegative = 0.0
    """The fix is lost ``1 + float_gain x blocked`` times as often. Left at open-sky
    rates: both navigations stand still through float (they fuse RTK-fixed positions
    only), so cross-track errors cannot calibrate it."""


def _rates(dwell_s: tuple[float, ...], exits: tuple[tuple[float, ...], ...]) -> list[list[float]]:
    """Rate matrix from mean dwell times and exit probabilities (rows sum to 1)."""
    return [[p / d for p in row] for d, row in zip(dwell_s, exits, strict=True)]


_DEFAULT_RATES = _rates(
    (600.0, 15.0, 10.0, 3.0),
    (
        (0.0, 0.80, 0.15, 0.05),  # FIX   -> FLOAT mostly (cycle slips)
        (0.90, 0.0, 0.08, 0.02),  # FLOAT -> FIX once ambiguities resolve
        (0.10, 0.85, 0.0, 0.05),  # SINGLE -> FLOAT as corrections arrive
        (0.0, 0.10, 0.90, 0.0),  # NO_FIX -> SINGLE first
    ),
)


class RtkModelConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Configuration of :class:`RtkErrorModel`; defaults are sourced in the module doc."""

    fix: StateNoise = StateNoise(h_const_m=0.007, v_const_m=0.014, correlation_time_s=2.0)
    """The error of an RTK-fixed solution."""
    float_: StateNoise = msgspec.field(
        name="float",
        default=StateNoise(h_const_m=0.25, v_const_m=0.5, correlation_time_s=30.0),
    )
    """The error of an RTK-float solution."""
    single: StateNoise = StateNoise(
        h_const_m=1.2, h_ppm=0.0, v_const_m=2.4, v_ppm=0.0, correlation_time_s=120.0
    )
    """The error of a single-point solution."""
    rates_per_s: list[list[NonNegative]] = msgspec.field(default_factory=lambda: _DEFAULT_RATES)
    """``rates_per_s[i][j]`` is the rate (1/s) of jumping from ``STATES[i]`` to
    ``STATES[j]`` (FIX, FLOAT, SINGLE, NO_FIX); the diagonal is ignored."""
    initial_state: FixQuality = FixQuality.FIX
    """The solution state at the start (a GGA fix quality)."""
    baseline_m: NonNegative = 400.0
    """The distance to the RTK base station (m), which the ``*_ppm`` terms scale."""
    canopy: CanopyConfig = msgspec.field(default_factory=CanopyConfig)
    """RTK under the crop."""

    def __post_init__(self) -> None:
        n = len(STATES)
        if len(self.rates_per_s) != n or any(len(r) != n for r in self.rates_per_s):
            raise ValueError(f"rates_per_s must be {n}x{n} (order {[s.name for s in STATES]})")
        if self.initial_state not in STATES:
            raise ValueError(f"initial_state {self.initial_state!r} is not one of {STATES}")

    def noise(self, state: FixQuality) -> StateNoise | None:
        """The noise of ``state``; ``None`` for NO_FIX (no position)."""
        return {
            FixQuality.FIX: self.fix,
            FixQuality.FLOAT: self.float_,
            FixQuality.SINGLE: self.single,
        }.get(state)


def sigma_enu(noise: StateNoise, baseline_m: float) -> npt.NDArray[np.float64]:
    """1-sigma (east, north, up) in metres at ``baseline_m`` from the base station."""
    ppm = 1e-6 * baseline_m
    h = noise.h_const_m + noise.h_ppm * ppm
    return np.array([h, h, noise.v_const_m + noise.v_ppm * ppm])


class RtkSample(msgspec.Struct, frozen=True, kw_only=True):
    """One epoch: the state, the position error to add to the truth (east, north, up,
    metres; ``None`` when NO_FIX) and the 1-sigma the receiver would report in GST."""

    state: FixQuality
    error_enu_m: tuple[float, float, float] | None
    sigma_enu_m: tuple[float, float, float] | None


class RtkErrorModel:
    """Stateful sampler: call :meth:`step` once per output epoch. Not thread-safe."""

    def __init__(self, cfg: RtkModelConfig, rng: np.random.Generator) -> None:
        self.cfg = cfg
        self._rng = rng
        self._rates = np.array(cfg.rates_per_s, dtype=float)
        np.fill_diagonal(self._rates, 0.0)
        self.state = cfg.initial_state
        # Unit-variance Gauss-Markov state, scaled by the current state's sigma, so a
        # FLOAT -> FIX jump shrinks the error at once, as a real fix does.
        self._z = rng.standard_normal(3)

    def step(self, dt_s: float, baseline_m: float | None = None, blocked: float = 0.0) -> RtkSample:
        """Advance by ``dt_s`` seconds (> 0) and return the new epoch. ``baseline_m``
        (distance to the base station) defaults to the configured one; ``blocked``:
        the share of the sky the crop hides (:class:`CanopyConfig`)."""
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s}")
        blocked = min(max(blocked, 0.0), 1.0) if math.isfinite(blocked) else 0.0
        self._transition(dt_s, 1.0 + self.cfg.canopy.float_gain * blocked)
        noise = self.cfg.noise(self.state)
        if noise is None:
            return RtkSample(state=self.state, error_enu_m=None, sigma_enu_m=None)
        a = math.exp(-dt_s / noise.correlation_time_s)
        self._z = a * self._z + math.sqrt(1.0 - a * a) * self._rng.standard_normal(3)
        sig = sigma_enu(noise, self.cfg.baseline_m if baseline_m is None else baseline_m)
        if self.state == FixQuality.FIX:
            sig = sig * (1.0 + self.cfg.canopy.noise_gain * blocked)
        err = sig * self._z
        return RtkSample(
            state=self.state,
            error_enu_m=(float(err[0]), float(err[1]), float(err[2])),
            sigma_enu_m=(float(sig[0]), float(sig[1]), float(sig[2])),
        )

    def _transition(self, dt_s: float, fix_exit: float = 1.0) -> None:
        # At most one jump per step: exact enough when dt is far below the dwell times.
        row = self._rates[STATES.index(self.state)]
        if self.state == FixQuality.FIX:
            row = row * fix_exit  # under the crop the fix is lost more often
        total = float(row.sum())
        if total <= 0.0 or self._rng.random() >= -math.expm1(-total * dt_s):
            return
        self.state = STATES[int(self._rng.choice(len(STATES), p=row / total))]


def stationary_distribution(cfg: RtkModelConfig) -> dict[FixQuality, float]:
    """Long-run fraction of time in each state (for checking a configuration)."""
    q = np.array(cfg.rates_per_s, dtype=float)
    np.fill_diagonal(q, 0.0)
    np.fill_diagonal(q, -q.sum(axis=1))
    # Solve pi Q = 0 with sum(pi) = 1 in the least-squares sense.
    a = np.vstack([q.T, np.ones(len(STATES))])
    b = np.zeros(len(STATES) + 1)
    b[-1] = 1.0
    pi = np.linalg.lstsq(a, b, rcond=None)[0]
    return {s: float(p) for s, p in zip(STATES, pi, strict=True)}
