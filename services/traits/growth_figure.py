"""A season's growth figure: one trait against time, per entry.

Matplotlib's object API on the Agg canvas (no pyplot, so no global figure state and
no display), written atomically so a reader never finds half a PNG.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from common.canopy import F64
from common.files import atomic_write

DPI = 150
# above this many entries a legend hides the plot; the title gives the count instead
MAX_LEGEND = 12


def growth_figure(
    path: Path | str,
    dates: Sequence[str],
    days: F64,
    values: F64,
    entries: Sequence[str],
    trait: str,
    unit: str,
) -> None:
    """Write ``trait`` (in ``unit``) of every plot on every date as a figure at
    ``path`` (format from its suffix, e.g. .png): per entry the mean over its
    replicates (NaN ignored) as a thick line with markers, each plot as a thin line
    of its entry's colour, plots without an entry ("") in grey. The x axis is
    ``days`` after planting when all are finite, else the date's index; ticks carry
    ``dates``. ``values`` is (dates, plots). Raises ValueError on mismatched lengths."""
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 2 or values.shape != (len(dates), len(entries)) or len(days) != len(dates):
        raise ValueError(
            f"values {values.shape} must be (dates, plots) = ({len(dates)}, {len(entries)}) "
            f"with {len(days)} days"
        )
    by_days = bool(len(days)) and bool(np.all(np.isfinite(days)))
    x = np.asarray(days, dtype=np.float64) if by_days else np.arange(len(dates), dtype=float)
    fig = Figure(figsize=(8, 5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    names = sorted({e for e in entries if e != ""})
    colours = _colours(len(names))
    col = np.asarray(entries, dtype=object)
    for orphan in np.flatnonzero(col == ""):
        ax.plot(x, values[:, orphan], color="0.6", lw=0.5)
    for name, c in zip(names, colours, strict=True):
        mine = values[:, col == name]
        for p in range(mine.shape[1]):
            ax.plot(x, mine[:, p], color=c, lw=0.5, alpha=0.6)
        seen = np.isfinite(mine).any(axis=1)
        # the mean only where a replicate was measured, so no all-NaN warning
        mean = np.full(len(x), np.nan)
        mean[seen] = np.nanmean(mine[seen], axis=1)
        ax.plot(x, mean, color=c, lw=2.0, marker="o", ms=4, label=name)
    ax.set_xticks(x)
    labels = [f"{d}\nday {t:g}" for d, t in zip(dates, x, strict=True)] if by_days else dates
    ax.set_xticklabels(list(labels), fontsize=8)
    ax.set_xlabel("date and days after planting" if by_days else "date")
    ax.set_ylabel(f"{trait} ({unit})")
    ax.set_title(f"{trait}: mean per entry (thick) and plots (thin), {len(names)} entries")
    if 0 < len(names) <= MAX_LEGEND:
        ax.legend(loc="upper left", fontsize=7, bbox_to_anchor=(1.0, 1.0))
    ax.grid(alpha=0.3)
    fig.tight_layout()
    dest = Path(path)
    atomic_write(dest, lambda p: fig.savefig(p, dpi=DPI, format=dest.suffix.lstrip(".") or "png"))


def _colours(n: int) -> list[tuple[float, float, float, float]]:
    """Qualitative colours, one per entry; they repeat past 20 entries, where the
    legend is off anyway."""
    k = 20 if n > 10 else 10
    m = colormaps[f"tab{k}"]
    return [m(i % k) for i in range(n)]
