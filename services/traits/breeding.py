"""What a breeder asks of one survey's traits next: per entry the mean and spread over
its replicates, per trait the heritability from the replicated design
(:mod:`.stats`). Written as ``entries.csv`` and ``heritability.csv`` beside
``traits.csv`` when the field book names entries, and summed up in ``traits.md``.

Only plots flagged ``ok`` count: an occluded plot's traits describe the part the
scanner saw, and would pass for a small plant."""

from __future__ import annotations

import csv
import io
import math

import numpy as np

from common.canopy import TRAITS
from services.traits.compute import OK, RunTraits, TraitTable
from services.traits.stats import Heritability, entry_summary, heritability

# traits of the plants (``points`` and ``seen`` describe the survey)
PLANT_TRAITS = tuple(t for t in TRAITS if t not in ("points", "seen"))


def _ok_values(table: TraitTable, trait: str) -> np.ndarray:
    ok = np.array([q == OK for q in table.quality])
    return np.where(ok, table.column(trait), np.nan)


def has_entries(table: TraitTable) -> bool:
    return any(r.entry for r in table.records)


def _num(v: float, digits: int = 4) -> str:
    return "" if not math.isfinite(v) else f"{v:.{digits}g}"


def entries_csv(table: TraitTable) -> str:
    """One row per entry: its replicates (``n``), then per trait its mean and SD over
    the replicates flagged ok (units in the header)."""
    entries = [r.entry for r in table.records]
    stats = {t: entry_summary(entries, _ok_values(table, t)) for t in PLANT_TRAITS}
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    head = ["entry", "plots"]
    for t in PLANT_TRAITS:
        u = TRAITS[t]
        head += [f"{t} mean ({u})", f"{t} sd ({u})", f"{t} n (1)"]
    w.writerow(head)
    first = stats[PLANT_TRAITS[0]]
    for k, e in enumerate(first):
        row = [e.entry, str(entries.count(e.entry))]
        for t in PLANT_TRAITS:
            s = stats[t][k]
            row += [_num(s.mean), _num(s.sd), str(s.n)]
        w.writerow(row)
    return buf.getvalue()


def heritabilities(table: TraitTable) -> dict[str, Heritability]:
    """Each plant trait's heritability over the plots flagged ok."""
    entries = [r.entry for r in table.records]
    reps = [r.rep for r in table.records]
    return {t: heritability(entries, reps, _ok_values(table, t)) for t in PLANT_TRAITS}


def heritability_csv(h2: dict[str, Heritability]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(
        [
            "trait",
            "h2_entry_mean (1)",
            "h2_plot (1)",
            "sigma2_g (unit^2)",
            "sigma2_e (unit^2)",
            "entries (1)",
            "plots (1)",
            "reps_harmonic_mean (1)",
            "model",
            "note",
        ]
    )
    for t, h in h2.items():
        w.writerow(
            [
                t,
                _num(h.h2_mean, 3),
                _num(h.h2_plot, 3),
                _num(h.sigma2_g),
                _num(h.sigma2_e),
                h.n_entries,
                h.n_plots,
                _num(h.r_mean, 3),
                h.model,
                h.reason,
            ]
        )
    return buf.getvalue()


def report(rt: RunTraits, h2: dict[str, Heritability] | None) -> str:
    """``traits.md``: the survey's plots and traits at a glance, heritability when the
    field book has a replicated design."""
    t = rt.table
    q = t.quality
    lines = [
        f"# Traits of {rt.mission or rt.run_dir.name}",
        "",
        f"Field {rt.layout.name!r}, {len(q)} plots; date {rt.date or 'unknown'}"
        + (f" ({rt.date_source})" if rt.date else "")
        + f". {q.count(OK)} plots ok, {len(q) - q.count(OK)} flagged.",
        "",
        "| trait | unit | median | min | max | method |",
        "|---|---|---|---|---|---|",
    ]
    for name in PLANT_TRAITS:
        v = _ok_values(t, name)
        v = v[np.isfinite(v)]
        cells = [_num(float(f(v))) if v.size else "" for f in (np.median, np.min, np.max)]
        lines.append(
            f"| {name} | {TRAITS[name]} | {' | '.join(cells)} | {t.definition.method(name)} |"
        )
    if h2:
        lines += [
            "",
            "## Heritability (broad sense, entry-mean basis)",
            "",
            "| trait | H2 | plot-basis H2 | entries | note |",
            "|---|---|---|---|---|",
        ]
        for name, h in h2.items():
            lines.append(
                f"| {name} | {_num(h.h2_mean, 3)} | {_num(h.h2_plot, 3)} | {h.n_entries} | "
                f"{h.reason or h.model} |"
            )
    return "\n".join(lines) + "\n"
