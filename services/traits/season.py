"""Pure functions over a season: several surveys of one field, per plot.

- ``vertical_offset``: how far one date's ground sits above another's on cells that
  hold no plants (lanes, headlands), so heights of two dates compare on one datum;
- ``growth`` / ``growth_rate``: per plot change between consecutive dates;
- ``fit_logistic`` / ``fit_all``: a per-plot logistic growth curve.

Arrays in, numbers out: no I/O, no logging. Heights in metres, days in days (after
planting, or any common origin); a trait's own unit otherwise (``common.canopy``).
"""

from __future__ import annotations

import math
import warnings

import msgspec
import numpy as np
import numpy.typing as npt
from scipy.optimize import OptimizeWarning, curve_fit

from common.canopy import F64

# 1.4826 = 1 / Phi^-1(3/4): scales the median absolute deviation to the standard
# deviation of a normal sample (Rousseeuw & Croux 1993, JASA 88:1273).
MAD_TO_SIGMA = 1.4826


def robust_sigma(v: npt.ArrayLike) -> float:
    """The SD of ``v``'s bulk, from its median absolute deviation (outliers aside)."""
    a = np.asarray(v, dtype=np.float64)
    return MAD_TO_SIGMA * float(np.median(np.abs(a - np.median(a))))


class Offset(msgspec.Struct, frozen=True, kw_only=True):
    """Vertical offset of a survey's ground against a reference survey's (metres).

    ``median_m``: median of ``ground - ground_ref`` over the common stable cells
    (positive: this date's ground sits higher); ``sigma_m``: its robust spread
    (1.4826 x MAD, Rousseeuw & Croux 1993); ``se_m``: the median's standard error,
    sqrt(pi/2) x sigma / sqrt(n) for normal errors (the median's asymptotic variance
    1 / (4 n f(m)^2), Kendall & Stuart, The Advanced Theory of Statistics, vol. 1);
    ``n_cells``: cells used. Two registrations can also differ by a tilt (each rests
    on navigation heights with centimetres of error per scan): ``plane`` (a, b, c) is
    the offset ``a + b (x - x0) + c (y - y0)`` fitted to the same cells (least squares
    with outliers beyond 3 sigma dropped), ``centre`` its (x0, y0) (None without cell
    coordinates); ``exceeds``: the offset, or the plane anywhere over the stable
    cells, is larger than ``tolerance_m``.
    """

    median_m: float
    sigma_m: float
    se_m: float
    n_cells: int
    tolerance_m: float
    exceeds: bool
    plane: tuple[float, float, float] | None = None
    centre: tuple[float, float] | None = None

    def at(self, x: F64, y: F64) -> F64:
        """The offset at field positions (x, y): the plane where there is one."""
        if self.plane is None or self.centre is None:
            return np.full(np.shape(x), self.median_m)
        a, b, c = self.plane
        return a + b * (np.asarray(x) - self.centre[0]) + c * (np.asarray(y) - self.centre[1])


def _plane(x: F64, y: F64, d: F64) -> tuple[tuple[float, float, float], tuple[float, float]]:
    """A plane through ``d`` over (x, y), refitted three times without the points
    beyond 3 robust sigma of it."""
    x0, y0 = float(np.median(x)), float(np.median(y))
    a = np.column_stack([np.ones_like(x), x - x0, y - y0])
    keep = np.ones(len(d), dtype=bool)
    coef: npt.NDArray[np.floating] = np.zeros(3)
    for _ in range(4):
        coef = np.linalg.lstsq(a[keep], d[keep], rcond=None)[0]
        r = d - a @ coef
        sigma = robust_sigma(r[keep])
        keep = np.abs(r) <= 3 * max(sigma, 1e-6)
    return (float(coef[0]), float(coef[1]), float(coef[2])), (x0, y0)


def vertical_offset(
    ground_ref: F64,
    ground: F64,
    stable: npt.NDArray[np.bool_],
    *,
    tolerance_m: float = 0.01,
    min_cells: int = 50,
    centres: tuple[F64, F64] | None = None,
) -> Offset:
    """The offset of ``ground`` against ``ground_ref``: two ground-height grids (m) of
    the same shape from two dates (NaN: no ground found there), compared on the cells
    ``stable`` marks (no plants, so the ground there did not change between dates).

    ``tolerance_m`` (default 1 cm): below it the dates agree within what registration
    achieves (the paper reports ~2 cm mean point errors for one registration; a median
    over many cells is tighter), so a smaller offset is noise and should not be
    subtracted. ``centres``: the cells' x and y (grids of the same shape), to fit
    the tilt between the dates too. Raises ValueError when the shapes differ or fewer
    than ``min_cells`` stable cells hold ground on both dates.
    """
    if ground_ref.shape != ground.shape or stable.shape != ground.shape:
        raise ValueError(
            f"ground grids and stable mask differ in shape: {ground_ref.shape}, "
            f"{ground.shape}, {stable.shape}"
        )
    diff = ground[stable] - ground_ref[stable]
    finite = np.isfinite(diff)
    diff = diff[finite]
    if diff.size < min_cells:
        raise ValueError(
            f"the dates share no stable ground ({diff.size} common stable cells, "
            f"need {min_cells}): are they the same field?"
        )
    med = float(np.median(diff))
    sigma = robust_sigma(diff)
    plane = centre = None
    largest = abs(med)
    if centres is not None:
        x, y = centres[0][stable][finite], centres[1][stable][finite]
        plane, centre = _plane(x, y, diff)
        a, b, c = plane
        corners = [a + b * (px - centre[0]) + c * (py - centre[1])
                   for px in (x.min(), x.max()) for py in (y.min(), y.max())]  # fmt: skip
        largest = max(largest, *(abs(v) for v in corners))
    return Offset(
        median_m=med,
        sigma_m=sigma,
        se_m=math.sqrt(math.pi / 2.0) * sigma / math.sqrt(diff.size),
        n_cells=int(diff.size),
        tolerance_m=tolerance_m,
        exceeds=largest > tolerance_m,
        plane=plane,
        centre=centre,
    )


def _check_season(values: F64, days: F64) -> None:
    if values.ndim != 2 or days.ndim != 1 or values.shape[0] != days.shape[0]:
        raise ValueError(
            f"values must be (dates, plots) and days (dates,): got {values.shape} and {days.shape}"
        )
    if days.size > 1 and not np.all(np.diff(days) > 0):
        raise ValueError(f"days must increase strictly: got {days.tolist()}")


def growth(values: F64, days: F64) -> F64:
    """Per plot change between consecutive dates, ``values[d + 1] - values[d]``: shape
    (D - 1, P) from ``values`` (D, P) on ``days`` (D,); NaN where either date is NaN.
    Raises ValueError on mismatched shapes or days that do not increase."""
    _check_season(values, days)
    return np.diff(values, axis=0)


def growth_rate(values: F64, days: F64) -> F64:
    """Absolute growth rate per day between consecutive dates, (D - 1, P): the change
    over the days between them (AGR = dY/dt, Hunt 1982, Plant Growth Curves).
    Raises ValueError as ``growth`` does."""
    _check_season(values, days)
    return np.diff(values, axis=0) / np.diff(days)[:, None]


class LogisticFit(msgspec.Struct, frozen=True, kw_only=True):
    """A logistic growth curve ``y = k / (1 + exp(-r (t - t0)))`` of one plot.

    ``k``: asymptote (the trait's unit); ``r``: relative rate at the start (1/day);
    ``t0``: inflection, where y = k/2 and growth is fastest, r k / 4 per day (days);
    ``rmse``: root mean square residual (the trait's unit); ``n``: dates used;
    ``dof``: residual degrees of freedom (n - 3); ``ok``: False when not fitted or not
    trustworthy (the parameters are then NaN or kept for inspection); ``reason``: why,
    or a caveat on an ok fit (empty when none).
    """

    k: float
    r: float
    t0: float
    rmse: float
    n: int
    dof: int
    ok: bool
    reason: str = ""

    def predict(self, t: F64) -> F64:
        """The curve at days ``t``."""
        return _logistic(t, self.k, self.r, self.t0)


def _logistic(t: F64, k: float, r: float, t0: float) -> F64:
    # exp overflows to inf for far-early t, which gives the right limit 0
    with np.errstate(over="ignore"):
        return k / (1.0 + np.exp(-r * (t - t0)))


def _not_fitted(n: int, reason: str) -> LogisticFit:
    nan = float("nan")
    return LogisticFit(
        k=nan, r=nan, t0=nan, rmse=nan, n=n, dof=max(0, n - 3), ok=False, reason=reason
    )


def _guess(t: F64, y: F64, k_hi: float, r_hi: float) -> tuple[float, float, float]:
    """Initial values: k a little above the largest value, t0 where the values first
    reach half of it, r such that the rise from 10 % to 90 % (2 ln 9 / r days) spans
    half the season; the optimiser starts inside its bounds."""
    k = min(1.1 * float(y.max()), 0.99 * k_hi)
    above = np.flatnonzero(y >= k / 2.0)
    t0 = float(t[above[0]]) if above.size else float(t[-1])
    span = float(t[-1] - t[0])
    r = min(2.0 * math.log(9.0) / max(span / 2.0, 1e-6), 0.5 * r_hi)
    return k, r, t0


def fit_logistic(
    days: F64,
    values: F64,
    *,
    k_max_factor: float = 10.0,
    r_max: float = 2.0,
) -> LogisticFit:
    """Fit ``y = k / (1 + exp(-r (t - t0)))`` to one plot's ``values`` on ``days``
    (the three-parameter logistic of plant growth analysis, Paine et al. 2012, Methods
    Ecol. Evol. 3:245, fitted per plot by non-linear least squares with
    ``scipy.optimize.curve_fit``, trust-region reflective within bounds).

    Bounds: 0 < k <= ``k_max_factor`` x the largest value; 0 < r <= ``r_max`` per day
    (2/day is a 10-90 % rise in 2.2 days, faster than any canopy); t0 within one
    season-length either side of the dates. Pairs with a NaN are dropped. Never
    raises: fewer than 3 dates, no positive value, an optimiser failure, k or r on a
    bound, or an inflection after the last date (the curve has not levelled off, or
    the data do not rise) give ``ok=False`` with the reason. Exactly 3 dates fit
    exactly: ok, with a reason saying no residual degrees of freedom are left.
    """
    t = np.asarray(days, dtype=np.float64).ravel()
    y = np.asarray(values, dtype=np.float64).ravel()
    if t.shape != y.shape:
        return _not_fitted(0, f"days {t.shape} and values {y.shape} differ in length")
    keep = np.isfinite(t) & np.isfinite(y)
    t, y = t[keep], y[keep]
    order = np.argsort(t)
    t, y = t[order], y[order]
    n = int(t.size)
    if n < 3:
        return _not_fitted(n, f"{n} dates with a value: a logistic needs at least 3")
    if float(y.max()) <= 0.0:
        return _not_fitted(n, "no positive value: nothing grew")
    span = float(t[-1] - t[0])
    if span <= 0.0:
        return _not_fitted(n, "all values on one day")
    k_hi = k_max_factor * float(y.max())
    lower = (1e-12, 1e-9, float(t[0]) - span)
    upper = (k_hi, r_max, float(t[-1]) + span)
    try:
        with warnings.catch_warnings():
            # with 3 points the covariance is undefined; the reason says so instead
            warnings.simplefilter("ignore", OptimizeWarning)
            popt, _ = curve_fit(
                _logistic,
                t,
                y,
                p0=_guess(t, y, k_hi, r_max),
                bounds=(lower, upper),
                method="trf",
                maxfev=5000,
            )
    except (RuntimeError, ValueError) as e:
        return _not_fitted(n, f"the fit failed: {str(e).splitlines()[0]}")
    k, r, t0 = (float(p) for p in popt)
    rmse = float(np.sqrt(np.mean((y - _logistic(t, k, r, t0)) ** 2)))
    reasons: list[str] = []
    ok = True
    # a parameter pinned on a bound is set by the bound, not by the data
    if k >= 0.999 * k_hi:
        ok = False
        reasons.append("k on its upper bound: the plot has not levelled off by the last date")
    if r >= 0.999 * r_max or r <= 1e-6:
        ok = False
        reasons.append(f"r = {r:.3g}/day on a bound: the values do not follow a rise")
    if t0 > t[-1]:
        ok = False
        reasons.append(
            "the inflection t0 lies after the last date: the plot has not "
            "levelled off, so k is an extrapolation"
        )
    elif t0 < t[0]:
        reasons.append("the inflection t0 lies before the first date: r is weakly determined")
    if n == 3:
        reasons.append("3 dates for 3 parameters: an exact fit with no residual degrees of freedom")
    return LogisticFit(k=k, r=r, t0=t0, rmse=rmse, n=n, dof=n - 3, ok=ok, reason="; ".join(reasons))


def fit_all(days: F64, values: F64) -> list[LogisticFit]:
    """``fit_logistic`` for every plot (column) of ``values`` (D, P) on ``days`` (D,).
    Raises ValueError on mismatched shapes (a caller's error, not bad data)."""
    if values.ndim != 2 or values.shape[0] != days.shape[0]:
        raise ValueError(
            f"values must be (dates, plots) matching days (dates,): got {values.shape} "
            f"and {days.shape}"
        )
    return [fit_logistic(days, values[:, p]) for p in range(values.shape[1])]
