"""A mission's per-plot traits on the dashboard: ``traits.csv`` -> coloured plot boxes.

The traits job writes ``<run_dir>/<mission>/traits.csv`` after registration, a row per
plot: ``plot,row,column,rep,entry`` (the field book's: row 1 the bottom row, column 1
the leftmost plot), a ``<trait> (<unit>)`` column per :data:`common.canopy.TRAITS`,
``quality`` (``ok``, ``occluded``, ``no points``) and ``date``; empty or ``nan``: not
measured. Each plot becomes a solid box on its footprint as tall as its measured
``height`` (a 2 cm slab without one), so the boxes read as the canopy, coloured by the
chosen trait on viridis over the plots measured ``ok``, grey when flagged or not
measured, its label (shown on hover) carrying the value and unit.

Pure file -> rows -> archetype arguments, but for :class:`TraitsWatch`, the shell's
half. A bad file raises :class:`TraitsError`, one line naming it; nothing is logged.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import logging
import math
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import rerun as rr

from common.arrays import F64, U8
from common.canopy import BOOK_COLUMNS, TRAITS, column
from common.field import Field
from common.files import read_regular
from common.messages.mission import MissionPhase, MissionState
from services.viz.config import VizConfig
from services.viz.scene import GREY, Entry

FIXED = BOOK_COLUMNS
MAX_BYTES = 32 * 1024 * 1024  # ~1.5 kB a plot at the field's 20 000-plot limit
FLAT = 0.02  # m, the slab drawn for a plot without a measured height
SETTLE_S = 1.0  # a file changed this recently may still be being written
NOT_MEASURED = ("", "nan")


class TraitsError(ValueError):
    """A traits file that cannot be drawn; the message is one line naming it."""


@dataclasses.dataclass(frozen=True)
class TraitRow:
    """One plot's line of a traits file (``line``: its 1-based line number)."""

    line: int
    plot: str
    row: int
    column: int
    rep: str
    entry: str
    quality: str
    values: dict[str, float]  # trait -> value, NaN where not measured


@dataclasses.dataclass(frozen=True)
class TraitBoxes:
    """The ``rr.Boxes3D`` arguments of one trait over the plots, and its colour range
    (``lo``, ``hi``: NaN when no plot was measured ``ok``)."""

    centers: F64  # (N, 3)
    half_sizes: F64  # (N, 3)
    colors: U8  # (N, 4)
    labels: list[str]
    lo: float
    hi: float
    grey: int  # plots flagged or not measured


def _number(cell: str, what: str, where: str) -> float:
    s = cell.strip()
    if s.lower() in NOT_MEASURED:
        return math.nan
    try:
        v = float(s)
    except ValueError:
        raise TraitsError(f"{where}: {what} {cell!r} is not a number") from None
    return v if math.isfinite(v) else math.nan


def _index(cell: str, what: str, where: str) -> int:
    try:
        v = int(cell.strip())
    except ValueError:
        v = 0
    if v < 1:
        raise TraitsError(f"{where}: {what} {cell!r} is not a whole number >= 1")
    return v


def parse(text: str, name: str) -> list[TraitRow]:
    """The plots of a traits file's ``text`` (``name`` goes into errors). Needs the
    field-book columns and ``quality``; trait columns are read where present."""
    try:
        lines = list(csv.reader(io.StringIO(text, newline="")))
    except csv.Error as exc:
        raise TraitsError(f"{name}: not CSV: {exc}") from None
    if not lines:
        raise TraitsError(f"{name}: empty")
    head = [h.strip() for h in lines[0]]
    missing = [c for c in (*FIXED, "quality") if c not in head]
    if missing:
        raise TraitsError(f"{name}: no column {', '.join(missing)} (header: {','.join(head)})")
    col = {h: i for i, h in enumerate(head)}
    rows = []
    for n, cells in enumerate(lines[1:], start=2):
        if not any(c.strip() for c in cells):
            continue  # a blank line, as spreadsheets leave at the end
        where = f"{name} line {n}"
        if len(cells) != len(head):
            raise TraitsError(f"{where}: {len(cells)} cells, the header has {len(head)}")
        cell = {h: cells[i].strip() for h, i in col.items()}
        values = {t: _number(cell[column(t)], column(t), where) for t in TRAITS if column(t) in col}
        rows.append(
            TraitRow(
                line=n,
                plot=cell["plot"],
                row=_index(cell["row"], "row", where),
                column=_index(cell["column"], "column", where),
                rep=cell["rep"],
                entry=cell["entry"],
                quality=cell["quality"],
                values=values,
            )
        )
    if not rows:
        raise TraitsError(f"{name}: no plot in the file")
    return rows


def read(path: Path) -> list[TraitRow]:
    """:func:`parse` of the file at ``path``; raises TraitsError."""
    try:
        text = read_regular(path, MAX_BYTES, "a traits file").decode("utf-8-sig")
    except (OSError, ValueError) as exc:  # UnicodeDecodeError is a ValueError
        raise TraitsError(f"{path}: cannot read: {exc}") from None
    return parse(text, str(path))


def value_text(trait: str, v: float) -> str:
    """``1.62 m``, ``0.83`` (unit 1), ``12345``; ``not measured`` for NaN."""
    if not math.isfinite(v):
        return "not measured"
    num = f"{v:.0f}" if abs(v) >= 1000 else f"{v:.3g}"
    unit = TRAITS[trait]
    return num if unit == "1" else f"{num} {unit}"


def label(r: TraitRow, trait: str) -> str:
    """``plot 101 G07 rep 1: height 1.62 m``, the quality appended when not ok."""
    who = " ".join(x for x in (f"plot {r.plot}", r.entry, f"rep {r.rep}" if r.rep else "") if x)
    flag = f" ({r.quality or 'no quality'})" if r.quality != "ok" else ""
    return f"{who}: {trait} {value_text(trait, r.values.get(trait, math.nan))}{flag}"


def viridis(t: F64) -> U8:
    """RGBA (N, 4) of ``t`` in [0, 1] on viridis: perceptually uniform, dark to
    light, so order reads without a legend and survives colour blindness."""
    from matplotlib import colormaps  # only once traits are drawn: a heavy import

    out: U8 = np.asarray(colormaps["viridis"](np.clip(t, 0.0, 1.0), bytes=True), dtype=np.uint8)
    return out


def plot_boxes(rows: list[TraitRow], field: Field, trait: str, name: str) -> TraitBoxes:
    """Each row's plot of ``field`` as a box coloured by ``trait``; raises TraitsError
    for a (row, column) that is no plot of the field or appears twice."""
    rc = zip(field.plot_row.tolist(), field.plot_col.tolist(), strict=True)
    at = {(r, c): p for p, (r, c) in enumerate(rc)}
    plots: list[int] = []
    taken: set[int] = set()
    for r in rows:
        p = at.get((r.row - 1, r.column - 1))
        if p is None:
            raise TraitsError(
                f"{name} line {r.line}: plot {r.plot} at row {r.row}, column {r.column} "
                f"is not a plot of field {field.name!r}"
            )
        if p in taken:
            raise TraitsError(f"{name} line {r.line}: row {r.row}, column {r.column} again")
        taken.add(p)
        plots.append(p)
    box = field.plot_boxes[plots]
    value = np.array([r.values.get(trait, math.nan) for r in rows])
    ok = np.array([r.quality == "ok" for r in rows]) & np.isfinite(value)
    lo, hi = (float(value[ok].min()), float(value[ok].max())) if ok.any() else (math.nan,) * 2
    # all plots alike (or one): the middle of the map, not its dark end
    t = np.where(ok, (value - lo) / (hi - lo), 0.5) if hi - lo > 1e-12 else np.full(len(ok), 0.5)
    colours = np.where(ok[:, None], viridis(t), np.array([*GREY, 255], dtype=np.uint8))
    height = np.array([r.values.get("height", math.nan) for r in rows])
    height = np.where(np.isfinite(height) & (height > FLAT), height, FLAT)
    centre = np.column_stack([(box[:, :2] + box[:, 3:5]) / 2, box[:, 2] + height / 2])
    half = np.column_stack([(box[:, 3:5] - box[:, :2]) / 2, height / 2])
    return TraitBoxes(
        centers=centre,
        half_sizes=half,
        colors=colours.astype(np.uint8),
        labels=[label(r, trait) for r in rows],
        lo=lo,
        hi=hi,
        grey=int((~ok).sum()),
    )


def entries(b: TraitBoxes, trait: str) -> list[Entry]:
    """The boxes at ``field/traits/<trait>`` and a mission-log line giving the colour
    scale, which rerun cannot draw as a legend."""
    scale = (
        f"{value_text(trait, b.lo)} (purple) to {value_text(trait, b.hi)} (yellow)"
        if math.isfinite(b.lo)
        else "no plot measured"
    )
    text = f"traits: plots coloured by {trait}, {scale}; {b.grey} grey (flagged or not measured)"
    return [
        Entry(
            f"field/traits/{trait}",
            rr.Boxes3D(
                centers=b.centers,
                half_sizes=b.half_sizes,
                colors=b.colors,
                labels=b.labels,
                fill_mode="solid",
            ),
        ),
        Entry("mission/log", rr.TextLog(text, level="INFO")),
    ]


def load(path: Path, field: Field, trait: str) -> list[Entry]:
    """The entries of the traits file at ``path``; raises TraitsError."""
    return entries(plot_boxes(read(path), field, trait, str(path)), trait)


class TraitsWatch:
    """When the shell reads a mission's traits file, and the job that draws it.

    Once the mission is done, its run folder's ``traits_file`` is read when it has been
    still for ``SETTLE_S`` (the traits job may be writing it), and again only when its
    mtime or size changes: a good file is drawn once, a bad one warned about once.
    ``field``: the plan's field, set by the shell; until known the file waits. The job
    runs on the shell's worker (``submit``) and hands its entries to ``draw``.
    """

    def __init__(
        self,
        cfg: VizConfig,
        draw: Callable[[int, list[Entry]], None],
        submit: Callable[[Callable[[], None]], None],
        log: logging.Logger,
    ) -> None:
        self.file, self.trait = cfg.traits_file, cfg.trait
        self.draw, self.submit, self.log = draw, submit, log
        self.field: Field | None = None
        self._seen: tuple[Path, int, int] | None = None

    def poll(self, run_dir: Path, state: MissionState | None) -> None:
        """Submit the job drawing ``state``'s mission's traits file when it is new."""
        field = self.field
        if state is None or state.phase != MissionPhase.DONE or field is None:
            return
        path, stamp_ns = run_dir / state.mission / self.file, state.stamp_ns
        try:
            st = path.stat()
        except OSError:
            return  # not written yet, or not visible from this machine
        key = (path, st.st_mtime_ns, st.st_size)
        if key == self._seen or time.time() - st.st_mtime < SETTLE_S:
            return
        self._seen = key

        def job() -> None:
            try:
                drawn = load(path, field, self.trait)
            except TraitsError as exc:
                self.log.warning("viz: traits not shown: %s", exc)
                return
            self.draw(stamp_ns, drawn)
            self.log.info("viz: %s shown as field/traits/%s", path, self.trait)

        self.submit(job)
