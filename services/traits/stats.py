"""What a breeder asks of one trait over the replicated design: per entry summaries
and broad-sense heritability.

Inputs are per plot, in the field book's order: ``entries`` (the entry, i.e. genotype,
sown there; "" for a plot without one, which is skipped), ``reps`` (its replicate or
block, None when unknown) and ``values`` (the trait, NaN when not measured, dropped).
Pure: no I/O, no logging; statsmodels' warnings become the result's ``reason``.
"""

from __future__ import annotations

import math
import statistics
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import msgspec
import numpy as np
import numpy.typing as npt

from common.canopy import F64


class EntryStat(msgspec.Struct, frozen=True, kw_only=True):
    """One entry's replicates: ``n`` non-NaN values, their mean, sample SD (ddof=1, NaN
    for n < 2), min and max (NaN for n = 0), in the trait's unit."""

    entry: str
    n: int
    mean: float
    sd: float
    min: float
    max: float


def entry_summary(entries: Sequence[str], values: F64) -> list[EntryStat]:
    """Per entry, sorted by name: mean, SD (ddof=1), n, min, max of its non-NaN
    values. Plots with entry "" are skipped. Raises ValueError when the lengths
    differ."""
    if len(entries) != len(values):
        raise ValueError(f"{len(entries)} entries but {len(values)} values")
    names = np.asarray(entries, dtype=object)
    out: list[EntryStat] = []
    nan = float("nan")
    for name in sorted({e for e in entries if e != ""}):
        v = values[names == name]
        v = v[np.isfinite(v)]
        n = int(v.size)
        out.append(
            EntryStat(
                entry=name,
                n=n,
                mean=float(v.mean()) if n else nan,
                sd=float(v.std(ddof=1)) if n >= 2 else nan,
                min=float(v.min()) if n else nan,
                max=float(v.max()) if n else nan,
            )
        )
    return out


class Heritability(msgspec.Struct, frozen=True, kw_only=True):
    """Broad-sense heritability of one trait from the replicated design.

    ``sigma2_g`` / ``sigma2_e``: genotypic and residual variance (the trait's unit
    squared); ``h2_mean``: on an entry-mean basis, sigma2_g / (sigma2_g + sigma2_e /
    r_mean) (Holland, Nyquist & Cervantes-Martinez 2003, Plant Breed. Rev. 22:9; the
    harmonic mean of replicates for unbalanced data); ``h2_plot``: on a plot basis,
    sigma2_g / (sigma2_g + sigma2_e) (Falconer & Mackay 1996, Introduction to
    Quantitative Genetics, ch. 10); ``n_entries`` / ``n_plots``: used; ``r_mean``:
    harmonic mean of replicates per entry; ``model``: how the components were
    estimated; ``ok``: False when they could not be (all numbers NaN); ``reason``: why,
    or a caveat (a sigma2_g on its boundary 0, which gives H2 = 0).
    """

    sigma2_g: float
    sigma2_e: float
    h2_mean: float
    h2_plot: float
    n_entries: int
    n_plots: int
    r_mean: float
    model: str
    ok: bool
    reason: str = ""


@dataclass(frozen=True)
class _Design:
    entry: npt.NDArray[np.str_]
    rep: npt.NDArray[np.int64] | None  # None: no usable rep, fit an intercept only
    y: F64
    note: str  # why the reps were not used, or ""


def _design(entries: Sequence[str], reps: Sequence[int | None], values: F64) -> _Design | str:
    """The plots kept (an entry and a finite value), or why the data cannot be used."""
    if not len(entries) == len(reps) == len(values):
        return f"lengths differ: {len(entries)} entries, {len(reps)} reps, {len(values)} values"
    keep = [
        i
        for i, (e, v) in enumerate(zip(entries, values, strict=True))
        if e != "" and math.isfinite(float(v))
    ]
    entry = np.array([entries[i] for i in keep], dtype=np.str_)
    y = np.asarray(values, dtype=np.float64)[keep]
    got = [reps[i] for i in keep]
    rep: npt.NDArray[np.int64] | None = None
    note = ""
    if got and all(r is not None for r in got):
        rep = np.array(got, dtype=np.int64)
        if np.unique(rep).size < 2:
            rep = None
    elif any(r is not None for r in got):
        note = "some plots have no rep: fitted without a rep effect"
    _, counts = np.unique(entry, return_counts=True)
    if int((counts >= 2).sum()) < 2:
        return (
            f"{int((counts >= 2).sum())} entries with >= 2 replicates: heritability "
            "needs at least 2"
        )
    return _Design(entry=entry, rep=rep, y=y, note=note)


def _result(d: _Design, s2g: float, s2e: float, model: str, reason: str) -> Heritability:
    _, counts = np.unique(d.entry, return_counts=True)
    r_mean = float(statistics.harmonic_mean(counts.tolist()))
    s2g = max(s2g, 0.0)
    total = s2g + s2e
    if not (math.isfinite(total) and total > 0.0):
        return _failed(
            model,
            "no variance between plots: heritability is undefined",
            counts.size,
            d.y.size,
            r_mean,
        )
    return Heritability(
        sigma2_g=s2g,
        sigma2_e=s2e,
        h2_mean=s2g / (s2g + s2e / r_mean),
        h2_plot=s2g / total,
        n_entries=int(counts.size),
        n_plots=int(d.y.size),
        r_mean=r_mean,
        model=model,
        ok=True,
        reason=reason,
    )


def _failed(
    model: str, reason: str, n_entries: int = 0, n_plots: int = 0, r_mean: float = float("nan")
) -> Heritability:
    nan = float("nan")
    return Heritability(
        sigma2_g=nan,
        sigma2_e=nan,
        h2_mean=nan,
        h2_plot=nan,
        n_entries=n_entries,
        n_plots=n_plots,
        r_mean=r_mean,
        model=model,
        ok=False,
        reason=reason,
    )


def import_statsmodels() -> None:
    """Import what :func:`heritability` fits with (a second or so): for a worker
    process to do ahead of its first fit (:mod:`.fits`)."""
    import pandas  # noqa: F401
    import statsmodels.formula.api  # noqa: F401


def heritability(entries: Sequence[str], reps: Sequence[int | None], values: F64) -> Heritability:
    """H2 from variance components of a linear mixed model fitted by REML (Patterson &
    Thompson 1971, Biometrika 58:545): entry random, rep fixed when every plot has one
    (else an intercept only), with statsmodels ``MixedLM``. Never raises: too few
    replicated entries, an optimiser that does not converge or a singular model give
    ``ok=False`` with the reason."""
    model = "REML mixed model: y ~ rep + (1|entry)"
    d = _design(entries, reps, values)
    if isinstance(d, str):
        return _failed(model, d)
    if d.rep is None:
        model = "REML mixed model: y ~ 1 + (1|entry)"
    import pandas as pd
    import statsmodels.formula.api as smf

    # statsmodels flags a variance below an absolute 0.01 as "on the boundary"; a
    # height in metres has variances far below that, so fit standardised values and
    # scale the components back
    centre, scale = float(d.y.mean()), float(d.y.std())
    if scale == 0.0:
        return _failed(model, "all values equal: heritability is undefined")
    frame = pd.DataFrame({"y": (d.y - centre) / scale, "entry": d.entry})
    formula = "y ~ 1"
    if d.rep is not None:
        frame["rep"] = d.rep
        formula = "y ~ C(rep)"
    fit, said = _fit_reml(smf.mixedlm(formula, frame, groups=frame["entry"]))
    if fit is None:
        return _failed(model, "the mixed model did not converge: " + "; ".join(said))
    s2g_std = float(np.asarray(fit.cov_re)[0, 0])
    # a derivative-free optimum on the boundary lands within its tolerance of 0, not
    # on it; below 1e-6 of the total variance sigma2_g is 0 for any breeding purpose
    s2g = 0.0 if s2g_std < 1e-6 else s2g_std * scale**2
    s2e = float(fit.scale) * scale**2
    zero = "sigma2_g estimated at 0 (its boundary): H2 = 0" if s2g == 0.0 else ""
    return _result(d, s2g, s2e, model, "; ".join(filter(None, [d.note, zero, *said])))


def _fit_reml(model: Any) -> tuple[Any | None, list[str]]:
    """The REML fit of a statsmodels ``MixedLM``, or None when no optimiser converged,
    with the warnings it raised (first lines, deduplicated).

    statsmodels' gradient optimisers (BFGS, L-BFGS, CG) fail to converge, or hit a
    singular matrix, when the optimum lies on the boundary sigma2_g = 0, a common case
    for a trait with no genetic signal; the derivative-free Powell and Nelder-Mead
    reach it, so they are tried next."""
    said: list[str] = []
    for method in (["bfgs", "lbfgs", "cg"], ["powell"], ["nm"]):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                fit = model.fit(reml=True, method=method)
            except (np.linalg.LinAlgError, ValueError) as e:
                said.append(f"{'/'.join(method)}: {str(e).splitlines()[0]}")
                continue
        if fit.converged:
            last = [str(w.message).splitlines()[0] for w in caught]
            if said:
                last.insert(0, f"converged with {method[0]} after: {'; '.join(said)}")
            return fit, list(dict.fromkeys(last))
        said.append(f"{'/'.join(method)} did not converge")
    return None, said


def heritability_anova(
    entries: Sequence[str], reps: Sequence[int | None], values: F64
) -> Heritability:
    """H2 from ANOVA (method-of-moments) variance components, a cross-check of
    ``heritability`` for balanced data: with reps, the randomised complete block
    ANOVA (entry + rep, one plot per entry and rep), else the one-way ANOVA with the
    same number of replicates per entry; sigma2_e = MS_error, sigma2_g = (MS_entry -
    MS_error) / r truncated at 0 (Searle, Casella & McCulloch 1992, Variance
    Components, ch. 3; for balanced data REML gives the same estimates when they are
    positive, ibid. ch. 6). Never raises: unbalanced data give ``ok=False``."""
    d = _design(entries, reps, values)
    model = "ANOVA (method of moments): y = mu + rep + entry + e"
    if isinstance(d, str):
        return _failed(model, d)
    names, ei = np.unique(d.entry, return_inverse=True)
    g = names.size
    counts = np.bincount(ei, minlength=g)
    r = int(counts[0])
    if not np.all(counts == r):
        return _failed(
            model,
            "unbalanced: the ANOVA estimate needs the same number of "
            "replicates for every entry; use heritability()",
        )
    grand = float(d.y.mean())
    means = np.bincount(ei, weights=d.y, minlength=g) / r
    ss_g = r * float(np.sum((means - grand) ** 2))
    if d.rep is None:
        model = "ANOVA (method of moments): y = mu + entry + e"
        ss_e = float(np.sum((d.y - means[ei]) ** 2))
        df_e = g * (r - 1)
    else:
        reps_u, ri = np.unique(d.rep, return_inverse=True)
        cells = np.bincount(ei * reps_u.size + ri, minlength=g * reps_u.size)
        if reps_u.size != r or not np.all(cells == 1):
            return _failed(
                model,
                "unbalanced: the block ANOVA needs every entry once in "
                "every rep; use heritability()",
            )
        rep_means = np.bincount(ri, weights=d.y) / g
        ss_e = float(np.sum((d.y - means[ei] - rep_means[ri] + grand) ** 2))
        df_e = (g - 1) * (r - 1)
    ms_g = ss_g / (g - 1)
    ms_e = ss_e / df_e
    s2g = (ms_g - ms_e) / r
    reason = "" if s2g > 0 else "MS_entry <= MS_error: sigma2_g truncated at 0"
    return _result(d, s2g, ms_e, model, "; ".join(filter(None, [d.note, reason])))
