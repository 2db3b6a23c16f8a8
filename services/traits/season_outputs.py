"""A season's files (:mod:`.series`), written atomically into one folder:

- ``season.csv``: one row per plot and date (field-book columns first), every trait
  with its unit, the quality flag, days after planting and the growth in height
  since the previous date (m and m/day);
- ``growth_fits.csv``: per plot its logistic growth curve of height (asymptote k,
  rate r, inflection t0, rmse, dates used, whether it could be trusted and why);
- ``season.md``: the dates, their vertical offsets on stable ground and whether
  heights were corrected by them, and heritability of height per date;
- ``growth.png``: height against days after planting per entry (:mod:`.growth_figure`).
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

import numpy as np

from common.canopy import column
from common.files import write_atomic
from services.traits.compute import NAMES
from services.traits.outputs import BOOK, book, cell
from services.traits.series import Season
from services.traits.stats import Heritability, heritability


def season_csv(s: Season) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(
        [
            *BOOK,
            "date",
            "days_after_planting (d)",
            *(column(n) for n in NAMES),
            "quality",
            "height_growth (m)",
            "height_growth_rate (m/d)",
        ]
    )
    for d, rt in enumerate(s.runs):
        t = rt.table
        for p, (r, vals, q) in enumerate(zip(t.records, t.values, t.quality, strict=True)):
            b = book(r)
            g = float(s.growth[d - 1, p]) if d else math.nan
            rate = g / (s.days[d] - s.days[d - 1]) if d else math.nan
            w.writerow(
                [
                    *("" if b[k] is None else b[k] for k in BOOK),
                    rt.date,
                    f"{s.days[d]:g}",
                    *(cell(n, float(v)) for n, v in zip(NAMES, vals, strict=True)),
                    q,
                    cell("height", g),
                    "" if not math.isfinite(rate) else f"{rate:.5f}",
                ]
            )
    return buf.getvalue()


def fits_csv(s: Season) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([*BOOK, "k (m)", "r (1/d)", "t0 (d)", "rmse (m)", "dates (1)", "ok", "note"])
    records = s.runs[0].table.records
    for r, f in zip(records, s.fits, strict=True):
        b = book(r)
        num = [f"{v:.4g}" if math.isfinite(v) else "" for v in (f.k, f.r, f.t0, f.rmse)]
        w.writerow([*("" if b[k] is None else b[k] for k in BOOK), *num, f.n, f.ok, f.reason])
    return buf.getvalue()


def _height_h2(s: Season, d: int) -> Heritability:
    """Heritability of height on date ``d`` over the plots flagged ok (``s.height``
    holds only those); the other traits' are in each run's heritability.csv."""
    recs = s.runs[d].table.records
    return heritability([r.entry for r in recs], [r.rep for r in recs], s.height[d])


def report(s: Season) -> str:
    first = s.runs[0]
    lines = [
        f"# Season of {first.layout.name!r}: {len(s.runs)} surveys",
        "",
        "Heights are measured above the first survey's ground, moved onto each date by "
        "the offset and tilt between the dates' stable ground (lanes, headlands) when "
        "they exceed the tolerance.",
        "",
        "| date | days after planting | survey | ground offset (mm) | tilt x, y (mm/m) | "
        "stable cells | corrected | plots ok | H2 of height |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for d, rt in enumerate(s.runs):
        off = s.offsets[d]
        shift = (
            "reference" if off is None else f"{off.median_m * 1000:+.1f} ± {off.se_m * 1000:.1f}"
        )
        cells = "" if off is None else str(off.n_cells)
        tilt = (
            ""
            if off is None or off.plane is None
            else (f"{off.plane[1] * 1000:+.2f}, {off.plane[2] * 1000:+.2f}")
        )
        h2 = _height_h2(s, d) if any(r.entry for r in rt.records) else None
        h2s = "" if h2 is None or not h2.ok else f"{h2.h2_mean:.3f}"
        ok = rt.table.quality.count("ok")
        lines.append(
            f"| {rt.date} | {s.days[d]:g} | {rt.run_dir.name} | {shift} | {tilt} | {cells} | "
            f"{'yes' if s.corrected[d] else 'no'} | {ok} | {h2s} |"
        )
    if s.fits:
        good = [f for f in s.fits if f.ok]
        k = np.array([f.k for f in good])
        lines += [
            "",
            f"Logistic growth curves of height: {len(good)} of {len(s.fits)} plots fitted"
            + (f", asymptote median {np.median(k):.3f} m" if good else "")
            + " (growth_fits.csv).",
        ]
    return "\n".join(lines) + "\n"


def write_season(s: Season, out: Path, figures: bool = True) -> list[str]:
    """Write the season's files into ``out``; the names written."""
    out.mkdir(parents=True, exist_ok=True)
    files = {"season.csv": season_csv(s), "season.md": report(s)}
    if s.fits:
        files["growth_fits.csv"] = fits_csv(s)
    for name, text in files.items():
        write_atomic(out / name, text.encode())
    names = list(files)
    if figures:
        from services.traits.growth_figure import growth_figure

        t = s.runs[-1].table
        growth_figure(
            out / "growth.png",
            [rt.date for rt in s.runs],
            s.days,
            s.height,
            [r.entry for r in t.records],
            "height",
            "m",
        )
        names.append("growth.png")
    return names
