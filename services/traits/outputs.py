"""The traits of one run as files (into ``RUN_DIR`` or ``--out``):

- ``traits.csv``: one row per plot; the field book's ``plot,row,column,rep,entry``
  first, then one column per trait with its unit (``height (m)``), ``quality`` and
  ``date``. Heights to the millimetre, volumes to 0.1 litre, shares to 0.001; an
  undefined trait (no canopy, no points) is an empty cell.
- ``traits_long.csv``: ``plot,trait,value,unit,date,method``, one row per plot and
  trait (empty value where undefined), the long format breeding databases import;
  ``method`` is :meth:`common.canopy.CanopyDefinition.method`.
- ``traits.geojson``: an RFC 7946 FeatureCollection, one Polygon per plot footprint
  with its field-book entry, traits, quality and date as properties. Coordinates are
  WGS84 lon, lat when the field is georeferenced; otherwise field-frame metres, which
  RFC 7946 has no way to declare: the foreign member ``phenorover.crs_note`` says so
  (a GIS will take them for degrees). ``phenorover.units`` gives each trait's unit.
- ``fieldmap.png`` (:mod:`.fieldmap`) and ``traits.toml``, the options it ran with.

Each file is written under a temporary name and renamed when complete, so an
interrupted run leaves the previous outputs (or none), never half a file.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from common.canopy import BOOK_COLUMNS, TRAITS, column
from common.config import dump_toml
from common.files import atomic_write, write_atomic
from services.traits.compute import NAMES, RunTraits, TraitTable
from services.traits.config import TraitsConfig
from services.traits.run import Record
from services.traits.stats import Heritability

BOOK = BOOK_COLUMNS
# decimals per unit: mm for heights, 0.1 L for volumes, 0.001 for shares
DECIMALS = {"m": 3, "m3": 4, "1": 3}
COUNTS = ("points",)


def rounded(trait: str, v: float) -> float | int | None:
    """``v`` at the trait's precision; None when undefined."""
    if not math.isfinite(v):
        return None
    if trait in COUNTS:
        return round(v)
    return round(v, DECIMALS.get(TRAITS[trait], 4))


def cell(trait: str, v: float) -> str:
    r = rounded(trait, v)
    if r is None:
        return ""
    if isinstance(r, int):
        return str(r)
    return f"{r:.{DECIMALS.get(TRAITS[trait], 4)}f}"


def book(r: Record) -> dict[str, Any]:
    """A record's field-book columns."""
    return {"plot": r.plot, "row": r.row, "column": r.column, "rep": r.rep, "entry": r.entry}


def header() -> list[str]:
    return [*BOOK, *(column(n) for n in NAMES), "quality", "date"]


def wide_csv(table: TraitTable) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header())
    for r, vals, q in zip(table.records, table.values, table.quality, strict=True):
        b = book(r)
        w.writerow(
            [
                *("" if b[k] is None else b[k] for k in BOOK),
                *(cell(n, float(v)) for n, v in zip(NAMES, vals, strict=True)),
                q,
                table.date,
            ]
        )
    return buf.getvalue()


def long_csv(table: TraitTable) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["plot", "trait", "value", "unit", "date", "method"])
    methods = {n: table.definition.method(n) for n in NAMES}
    for r, vals in zip(table.records, table.values, strict=True):
        for n, v in zip(NAMES, vals, strict=True):
            w.writerow([r.plot, n, cell(n, float(v)), TRAITS[n], table.date, methods[n]])
    return buf.getvalue()


def _rings(rt: RunTraits) -> tuple[list[list[list[float]]], str | None]:
    """Every plot's footprint ring (counter-clockwise, closed) and the CRS note (None:
    WGS84 lon, lat)."""
    b = rt.field.plot_boxes
    xs = b[:, [0, 3, 3, 0, 0]]
    ys = b[:, [1, 1, 4, 4, 1]]
    xy = np.stack([xs, ys], axis=-1).reshape(-1, 2)
    note = None
    if rt.layout.georeferenced:
        from common.field_geojson import field_to_wgs84

        xy = np.round(field_to_wgs84(rt.layout, xy), 9)  # 9 decimals: 0.1 mm
    else:
        xy = np.round(xy, 4)
        note = (
            f"field {rt.layout.name!r} is not georeferenced: coordinates are field-frame "
            "metres (x along the rows, y across, origin at the field's lower-left "
            "corner), not WGS84"
        )
    return xy.reshape(len(b), 5, 2).tolist(), note


def geojson(rt: RunTraits) -> dict[str, Any]:
    """The FeatureCollection (see the module docstring)."""
    t = rt.table
    rings, note = _rings(rt)
    features = []
    for r, vals, q, ring in zip(t.records, t.values, t.quality, rings, strict=True):
        props = {**book(r), **{n: rounded(n, float(v)) for n, v in zip(NAMES, vals, strict=True)}}
        props.update(quality=q, date=t.date)
        features.append(
            {
                "type": "Feature",
                "geometry": {"type": "Polygon", "coordinates": [ring]},
                "properties": props,
            }
        )
    meta: dict[str, Any] = {
        "field": rt.layout.name,
        "mission": rt.mission,
        "date": t.date,
        "units": dict(TRAITS),
        "crs": "WGS84 lon, lat (RFC 7946)" if note is None else "field frame (m)",
    }
    if note is not None:
        meta["crs_note"] = note
    return {"type": "FeatureCollection", "phenorover": meta, "features": features}


def options_toml(rt: RunTraits, cfg: TraitsConfig) -> str:
    """``traits.toml``: the options, with the date and where it came from as comments
    (the date is the run's, not an option)."""
    when = f"{rt.date} ({rt.date_source})" if rt.date else "unknown"
    return f"# phenorover traits {rt.run_dir}\n# date: {when}\n{dump_toml(cfg)}"


def write_outputs(
    rt: RunTraits,
    cfg: TraitsConfig,
    out: Path,
    h2: Callable[[], dict[str, Heritability]] | None = None,
) -> list[str]:
    """Write every output of one run into ``out``; returns the names written. ``h2``:
    where the run's heritabilities come from when its field book names entries (a
    worker's :meth:`.fits.Fits.next`; default: fitted here)."""
    out.mkdir(parents=True, exist_ok=True)
    t = rt.table
    files = {
        "traits.csv": wide_csv(t),
        "traits_long.csv": long_csv(t),
        "traits.geojson": json.dumps(geojson(rt), indent=1, allow_nan=False),
    }
    for name, text in files.items():
        write_atomic(out / name, text.encode())
    names = list(files)
    if cfg.figures:
        from services.traits.fieldmap import draw

        atomic_write(out / "fieldmap.png", lambda p: draw(rt, p))
        names.append("fieldmap.png")
    if rt.crop is not None:  # what `phenorover plan --from-survey` plans on
        from common.cropmodel import write as write_crop

        write_crop(out / "crop.json", rt.crop)
        names.append("crop.json")
    from services.traits import breeding

    fitted = None
    if breeding.has_entries(t):
        write_atomic(out / "entries.csv", breeding.entries_csv(t).encode())
        fitted = breeding.heritabilities(t) if h2 is None else h2()
        write_atomic(out / "heritability.csv", breeding.heritability_csv(fitted).encode())
        names += ["entries.csv", "heritability.csv"]
    write_atomic(out / "traits.md", breeding.report(rt, fitted).encode())
    names.append("traits.md")
    write_atomic(out / "traits.toml", options_toml(rt, cfg).encode())
    names.append("traits.toml")
    return names
