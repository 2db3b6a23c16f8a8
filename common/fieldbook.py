"""Field books: one :class:`PlotRecord` per plot (plot id, row, column, entry, rep),
Breedbase's convention: row 1 the bottom row of plots, column 1 the leftmost. A book comes
from a CSV file (:func:`read_csv`, named by a TOML layout's ``field_book``, read by
:func:`resolve`), a TOML ``[[field_book]]`` table or GeoJSON feature properties
(:func:`from_properties`); :func:`check` holds it against the field's plots and
:func:`records` gives one record per plot, in plot order."""

from __future__ import annotations

import csv
import io
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import msgspec

from common.arrays import I64
from common.field_model import (
    MAX_PLOTS,
    Field,
    FieldError,
    FieldLayout,
    PlotRecord,
    read_bounded,
)

__all__ = [
    "ALIASES",
    "check",
    "entries",
    "from_properties",
    "label",
    "read_csv",
    "records",
    "resolve",
]

# Header names (compared in lower case) by the key they fill, the preferred first:
# Breedbase's exports carry both plot_number (the field-book number) and plot_name,
# and both rep_number and block_number.
ALIASES: dict[str, tuple[str, ...]] = {
    "plot": ("plot", "plot_id", "plot_number", "plot_name"),
    "entry": ("entry", "genotype", "accession", "accession_name", "germplasmname"),
    "rep": ("rep", "rep_number", "replicate", "block", "block_number"),
    "row": ("row", "row_number"),
    "column": ("column", "col", "col_number", "column_number"),
}
REQUIRED = ("plot", "row", "column")


def _one_line(exc: Exception) -> str:
    return " ".join(str(exc).split())


def _read_text(path: Path) -> str:
    """The text of a field book file (:func:`read_bounded`); a spreadsheet's UTF-8
    byte-order mark is dropped."""
    data = read_bounded(path, "a field book")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise FieldError(f"{path}: not UTF-8 text (byte {exc.start})") from None


def _columns(header: list[str], where: str) -> dict[str, int]:
    """Column index of each key the header names; FieldError when plot, row or column
    is missing (the header itself is not echoed: the file may be anything)."""
    names = [h.strip().lower() for h in header]
    cols: dict[str, int] = {}
    for key, aliases in ALIASES.items():
        hit = next((names.index(a) for a in aliases if a in names), None)
        if hit is not None:
            cols[key] = hit
        elif key in REQUIRED:
            raise FieldError(f"{where}: no {key} column (header names: {', '.join(aliases)})")
    return cols


def _int(text: str, key: str, where: str) -> int:
    try:
        return int(text)
    except ValueError:
        shown = text if len(text) <= 20 else text[:20] + "..."
        raise FieldError(f"{where}: {key} {shown!r} is not an integer") from None


def _convert(raw: dict[str, Any], where: str) -> PlotRecord:
    try:
        return msgspec.convert(raw, PlotRecord)
    except msgspec.ValidationError as exc:
        raise FieldError(f"{where}: {_one_line(exc)}") from None


def _csv_record(cells: list[str], cols: dict[str, int], where: str) -> PlotRecord:
    def cell(key: str) -> str:
        i = cols.get(key)
        return cells[i].strip() if i is not None and i < len(cells) else ""

    raw: dict[str, Any] = {"plot": cell("plot"), "entry": cell("entry")}
    if not raw["plot"]:
        raise FieldError(f"{where}: empty plot id")
    for key in ("row", "column"):
        raw[key] = _int(cell(key), key, where)
    raw["rep"] = _int(cell("rep"), "rep", where) if cell("rep") else None
    return _convert(raw, where)


def read_csv(path: Path) -> tuple[PlotRecord, ...]:
    """The records of a field-book CSV (comma, semicolon or tab separated): a header
    line naming at least the plot, row and column columns (case-insensitive, with the
    :data:`ALIASES`, Breedbase's included; other columns are ignored), then one line per
    plot. Raises FieldError, one line naming the file and line."""
    text = _read_text(path)
    first = text.split("\n", 1)[0]
    # a spreadsheet saved in a comma-decimal locale separates with ";", a copy from
    # one pasted into an editor with tabs
    delim = max(",;\t", key=first.count) if first else ","
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=delim)
    out: list[PlotRecord] = []
    cols: dict[str, int] | None = None
    try:
        for cells in reader:
            where = f"{path}:{reader.line_num}"
            if not any(c.strip() for c in cells):
                continue
            if cols is None:
                cols = _columns(cells, where)
                continue
            if len(out) >= MAX_PLOTS:
                raise FieldError(f"{where}: more than the {MAX_PLOTS:,} plots a field may have")
            out.append(_csv_record(cells, cols, where))
    except csv.Error as exc:
        raise FieldError(f"{path}:{reader.line_num}: {_one_line(exc)}") from None
    if cols is None:
        raise FieldError(f"{path}: empty, expected a header line naming plot, row, column")
    return tuple(out)


def resolve(layout: FieldLayout, folder: Path, source: str) -> FieldLayout:
    """``layout`` with a CSV ``field_book`` (a path relative to ``folder``, the field
    file's) replaced by its records, so what travels downstream (plans included) holds
    records only. The CSV must lie in ``folder`` or below it: a service that confines
    field files to its folders would otherwise read any file a field names. Raises
    FieldError naming ``source`` and the CSV."""
    book = layout.field_book
    if not isinstance(book, str):
        return layout
    path = folder / book
    try:
        inside = path.resolve().is_relative_to(folder.resolve())
    except (OSError, RuntimeError):  # a symlink loop
        inside = False
    if not inside:
        raise FieldError(
            f"{source}: field book {book!r} is outside the field file's folder {folder}"
        )
    try:
        recs = read_csv(path)
    except FieldError as exc:
        raise FieldError(f"{source}: field book {exc}") from None
    return msgspec.structs.replace(layout, field_book=recs)


def _positions(field: Field) -> list[tuple[int, int]]:
    """(row, column) of every plot in the field-book convention (from 1), plot order."""
    rows, cols = (field.plot_row + 1).tolist(), (field.plot_col + 1).tolist()
    return list(zip(rows, cols, strict=True))


def label(layout: FieldLayout, folder: Path) -> str:
    """What errors call ``layout``'s book: ``field book PATH`` for one a CSV file holds
    (taken before :func:`resolve` replaces its name by its records), else ``field book``."""
    book = layout.field_book
    return f"field book {folder / book}" if isinstance(book, str) else "field book"


def check(layout: FieldLayout, field: Field, source: str, book_label: str = "field book") -> None:
    """Raise FieldError (one line naming ``source``, ``book_label`` (:func:`label`), the
    first offending plot and how many are wrong) unless ``layout``'s book is empty or
    matches ``field``'s plots exactly: unique plot ids, one record per (row, column),
    every record at a plot of the field and every plot with a record. A book still naming
    a CSV file is refused (read it first: :func:`resolve`)."""
    book = layout.field_book
    where = f"{source}: {book_label}"
    if isinstance(book, str):
        raise FieldError(f"{where} {book!r} is a file that was not read (load the field file)")
    if not book:
        return
    ids = Counter(r.plot for r in book)
    dup_ids = [k for k, n in ids.items() if n > 1]
    if dup_ids:
        raise FieldError(
            f"{where}: plot id {dup_ids[0]!r} appears {ids[dup_ids[0]]} times "
            f"({len(dup_ids)} plot ids repeated)"
        )
    at: dict[tuple[int, int], list[str]] = {}
    for r in book:
        at.setdefault((r.row, r.column), []).append(r.plot)
    shared = [(k, v) for k, v in at.items() if len(v) > 1]
    if shared:
        (row, col), names = shared[0]
        raise FieldError(
            f"{where}: plots {', '.join(map(repr, names))} are all at row {row} column {col} "
            f"({len(shared)} positions with more than one record)"
        )
    plots = _positions(field)
    known = set(plots)
    outside = [r for r in book if (r.row, r.column) not in known]
    if outside:
        r = outside[0]
        raise FieldError(
            f"{where}: plot {r.plot!r} at row {r.row} column {r.column} is not a plot of "
            f"field {field.name!r} ({len(outside)} of {len(book)} records outside its "
            f"{field.n_plots} plots)"
        )
    missing = [rc for rc in plots if rc not in at]
    if missing:
        row, col = missing[0]
        raise FieldError(
            f"{where}: no record for the plot at row {row} column {col} "
            f"({len(missing)} of the field's {field.n_plots} plots have none)"
        )


def records(layout: FieldLayout, field: Field) -> list[PlotRecord]:
    """One record per plot ``p`` of ``field`` in plot order (plot ``p`` is at
    ``field.plot_row[p]``, ``field.plot_col[p]``). Without a book: ``plot = p + 1`` and
    the plot's row and column. Raises FieldError when the book does not match."""
    plots = _positions(field)
    if not layout.field_book:
        return [PlotRecord(plot=str(p + 1), row=r, column=c) for p, (r, c) in enumerate(plots)]
    check(layout, field, f"field {layout.name!r}")
    assert not isinstance(layout.field_book, str)  # check refuses an unread CSV
    by_pos = {(r.row, r.column): r for r in layout.field_book}
    return [by_pos[rc] for rc in plots]


def entries(layout: FieldLayout, field: Field) -> list[str]:
    """The entry (genotype) of every plot in plot order ("" where none is given)."""
    return [r.entry for r in records(layout, field)]


def _text(value: object, key: str, where: str) -> str:
    # GIS tools write numeric plot ids as numbers (101, or 101.0 from a float column)
    if isinstance(value, str):
        return value.strip()
    if isinstance(value, int) and not isinstance(value, bool):
        return str(value)
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    raise FieldError(f"{where}: {key}={value!r} is neither text nor a whole number")


def _lookup(props: Mapping[str, Any], key: str) -> Any:
    return next((props[a] for a in ALIASES[key] if props.get(a) is not None), None)


def from_properties(
    props: Sequence[Mapping[str, Any] | None], row: I64, col: I64, source: str
) -> tuple[PlotRecord, ...]:
    """The book of GeoJSON plot features: ``props[i]`` the properties of feature ``i``,
    which the field puts at ``row[i]``, ``col[i]`` (from 0). Read keys (case-insensitive):
    plot id, entry and rep under the :data:`ALIASES`; empty when no feature has a plot
    id or entry. When no feature has a plot id, plot ``i`` is ``i + 1``; when some do,
    all must. Raises FieldError naming ``source`` and the feature."""
    low = [{str(k).lower(): v for k, v in (p or {}).items()} for p in props]
    with_id = any(_lookup(d, "plot") is not None for d in low)
    if not with_id and all(_lookup(d, "entry") is None for d in low):
        return ()
    out: list[PlotRecord] = []
    for i, d in enumerate(low):
        where = f"{source}: feature {i}"
        pid, entry, rep = (_lookup(d, k) for k in ("plot", "entry", "rep"))
        if pid is None and with_id:
            raise FieldError(f"{where} has no plot property (other features have one)")
        raw: dict[str, Any] = {
            "plot": _text(pid, "plot", where) if pid is not None else str(i + 1),
            "row": int(row[i]) + 1,
            "column": int(col[i]) + 1,
            "entry": _text(entry, "entry", where) if entry is not None else "",
        }
        if rep is not None and rep != "":
            raw["rep"] = _int(_text(rep, "rep", where), "rep", where)
        out.append(_convert(raw, where))
    return tuple(out)
