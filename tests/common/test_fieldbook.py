"""Field books: the shipped trial, CSV (Breedbase headers), TOML tables, GeoJSON
properties, the plan round trip, default records, and one-line errors naming the file."""

from __future__ import annotations

import datetime
import json
from collections import Counter
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest

from common import fieldbook
from common.field import FieldError, FieldLayout, build_field, example_names, load_field
from common.field_model import PlotRecord
from common.geo import FieldFrame
from common.messages.plan import PlanRequest

# a 2 x 3 field: rows 1-2 (bottom to top), columns 1-3 (left to right)
SMALL = """name = "small"
rows = 2
plots_per_row = 3
plot_length = 2.5
plot_width = 1.2
plot_height = 1.5
row_spacing = 1.0
alley_width = 1.6
headland_width = 2.0
edge_width = 1.5
"""
GOOD_CSV = "plot,row,column,rep,entry\n" + "".join(
    f"{10 + k},{k // 3 + 1},{k % 3 + 1},{k // 3 + 1},E{k % 3}\n" for k in range(6)
)


def _toml(tmp_path: Path, extra: str = "", csv: str | None = None) -> Path:
    """A SMALL field TOML in ``tmp_path`` (plus ``extra``), with ``book.csv`` beside it
    holding ``csv`` when given (and named as its field_book)."""
    path = tmp_path / "small.toml"
    if csv is not None:
        (tmp_path / "book.csv").write_text(csv)
        extra = 'field_book = "book.csv"\n' + extra
    path.write_text(SMALL + extra)
    return path


def _one_line_error(path: Path, *names: Path) -> str:
    with pytest.raises(FieldError) as info:
        load_field(path)
    msg = str(info.value)
    assert "\n" not in msg
    for name in (path, *names):
        assert str(name) in msg
    return msg


def test_the_shipped_trial_has_20_entries_in_3_complete_blocks() -> None:
    layout, fld = load_field("trial")
    assert layout.planting_date == datetime.date(2026, 5, 1)
    assert isinstance(layout.field_book, tuple) and len(layout.field_book) == 60
    recs = fieldbook.records(layout, fld)
    assert [(r.row, r.column) for r in recs] == list(
        zip((fld.plot_row + 1).tolist(), (fld.plot_col + 1).tolist(), strict=True)
    )
    assert Counter(r.rep for r in recs) == {1: 20, 2: 20, 3: 20}
    for rep in (1, 2, 3):
        block = [r for r in recs if r.rep == rep]
        assert sorted(r.entry for r in block) == [f"G{k:02d}" for k in range(1, 21)]
        assert sorted(int(r.plot) for r in block) == list(range(rep * 100 + 1, rep * 100 + 21))
    # serpentine: plot 107 (rep 1, 7th) is at the right end of row 2
    assert {r.plot: (r.row, r.column) for r in recs}["107"] == (2, 6)
    assert fieldbook.entries(layout, fld) == [r.entry for r in recs]
    # same geometry as ENGR; the CSV is not an example field
    engr, engr_fld = load_field("engr")
    assert np.array_equal(engr_fld.plot_boxes, fld.plot_boxes)
    assert layout.targets == engr.targets
    assert "trial" in example_names() and "trial.csv" not in " ".join(example_names())


def test_breedbase_headers_are_read_and_extra_columns_ignored(tmp_path: Path) -> None:
    rows = [
        "studyName,Plot_Name,germplasmName,PLOT_NUMBER,block_number,rep_number,row_number,"
        "col_number,is_a_control"
    ]
    for k in range(6):
        rows.append(f"t1,t1-plot{k},ACC{k},{100 + k},1,{k // 3 + 1},{k // 3 + 1},{k % 3 + 1},0")
    layout, fld = load_field(_toml(tmp_path, csv="\n".join(rows) + "\n"))
    recs = fieldbook.records(layout, fld)
    # plot_number (the field-book number) wins over plot_name, rep_number over block
    assert recs[0] == PlotRecord(plot="100", row=1, column=1, entry="ACC0", rep=1)
    assert recs[5] == PlotRecord(plot="105", row=2, column=3, entry="ACC5", rep=2)


def test_semicolons_a_byte_order_mark_and_blank_cells(tmp_path: Path) -> None:
    text = "\ufeffPlot;Row;Col;Block\n" + "".join(
        f"p{k};{k // 3 + 1};{k % 3 + 1};\n" for k in range(6)
    )
    layout, fld = load_field(_toml(tmp_path, csv=text))
    assert fieldbook.records(layout, fld)[4] == PlotRecord(plot="p4", row=2, column=2)


def test_an_inline_field_book_table(tmp_path: Path) -> None:
    tables = "".join(
        f'[[field_book]]\nplot = "{k}"\nrow = {k // 3 + 1}\ncolumn = {k % 3 + 1}\n'
        f'entry = "E{k}"\nrep = 1\n'
        for k in range(6)
    )
    layout, fld = load_field(_toml(tmp_path, "planting_date = 2026-04-20\n" + tables))
    assert layout.planting_date == datetime.date(2026, 4, 20)
    assert fieldbook.entries(layout, fld) == [f"E{k}" for k in range(6)]


def _geojson(tmp_path: Path, props: list[dict[str, Any]], **settings: Any) -> Path:
    """The SMALL field's plots as WGS84 polygons (rows at 30 deg), feature ``i`` with
    ``props[i]``, in plot order (row by row from the bottom)."""
    frame = FieldFrame(52.0, 5.0, 0.0, 30.0)
    feats = []
    boxes = build_field(msgspec.toml.decode(SMALL, type=FieldLayout)).plot_boxes
    for b, p in zip(boxes, props, strict=True):
        lat, lon, _ = frame.field_to_wgs84(b[[0, 3, 3, 0, 0]], b[[1, 1, 4, 4, 1]])
        ring = [[float(a), float(c)] for a, c in zip(lon, lat, strict=True)]
        geom = {"type": "Polygon", "coordinates": [ring]}
        feats.append({"type": "Feature", "geometry": geom, "properties": p})
    doc = {
        "type": "FeatureCollection",
        "features": feats[::-1],  # any order: rows and columns come from the geometry
        "phenorover": {"row_bearing_deg": 30.0, **settings},
    }
    path = tmp_path / "plots.geojson"
    path.write_text(json.dumps(doc))
    return path


def test_geojson_feature_properties_make_the_book(tmp_path: Path) -> None:
    props = [{"plot_number": 101 + k, "germplasmName": f"G{k}", "block": "2"} for k in range(6)]
    layout, fld = load_field(_geojson(tmp_path, props, planting_date="2026-05-01"))
    assert layout.planting_date == datetime.date(2026, 5, 1)
    by_plot = {r.plot: r for r in fieldbook.records(layout, fld)}
    assert by_plot["101"] == PlotRecord(plot="101", row=1, column=1, entry="G0", rep=2)
    assert by_plot["106"] == PlotRecord(plot="106", row=2, column=3, entry="G5", rep=2)


def test_geojson_entries_without_plot_ids_and_plots_without_properties(tmp_path: Path) -> None:
    layout, fld = load_field(_geojson(tmp_path, [{"entry": f"E{k}"} for k in range(6)]))
    assert sorted(fieldbook.entries(layout, fld)) == [f"E{k}" for k in range(6)]
    layout, _ = load_field(_geojson(tmp_path, [{"height": 1.0}] * 6))
    assert layout.field_book == ()
    shipped, fld = load_field("example_plots")  # its plot properties make a book
    assert [r.plot for r in fieldbook.records(shipped, fld)][:2] == ["P01", "P02"]


def test_geojson_book_errors_name_the_file_and_feature(tmp_path: Path) -> None:
    props: list[dict[str, Any]] = [{"plot": f"P{k}"} for k in range(6)]
    props[2] = {"entry": "E"}
    assert "has no plot property" in _one_line_error(_geojson(tmp_path, props))
    props[2] = {"plot": "P0"}
    assert "'P0' appears 2 times" in _one_line_error(_geojson(tmp_path, props))
    props[2] = {"plot": "P2", "rep": "first"}
    assert "rep 'first' is not an integer" in _one_line_error(_geojson(tmp_path, props))


@pytest.mark.parametrize("message", ["json", "msgpack"])
def test_a_plan_carries_the_book_and_planting_date(message: str) -> None:
    layout, _ = load_field("trial")
    codec: Any = msgspec.json if message == "json" else msgspec.msgpack
    assert codec.decode(codec.encode(layout), type=FieldLayout) == layout
    req = PlanRequest(layout=layout)
    assert codec.decode(codec.encode(req), type=PlanRequest).layout == layout


def test_default_records_are_numbered_in_plot_order() -> None:
    layout, fld = load_field("engr")
    recs = fieldbook.records(layout, fld)
    assert len(recs) == 60 and layout.field_book == () and layout.planting_date is None
    assert recs[0] == PlotRecord(plot="1", row=1, column=1)
    assert recs[7] == PlotRecord(plot="8", row=2, column=2)
    assert recs[59] == PlotRecord(plot="60", row=10, column=6)


def _edit(line: int, new: str) -> str:
    lines = GOOD_CSV.splitlines()
    lines[line] = new
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(
    ("csv", "needle"),
    [
        (_edit(2, "10,1,2,1,E1"), "plot id '10' appears 2 times (1 plot ids repeated)"),
        (_edit(2, "11,1,1,1,E1"), "'10', '11' are all at row 1 column 1"),
        (_edit(2, "11,3,2,1,E1"), "plot '11' at row 3 column 2 is not a plot of field"),
        (GOOD_CSV.rsplit("\n", 2)[0] + "\n", "no record for the plot at row 2 column 3"),
        (_edit(2, "11,one,2,1,E1"), "book.csv:3: row 'one' is not an integer"),
        (_edit(2, ",1,2,1,E1"), "book.csv:3: empty plot id"),
        (_edit(2, "11,1,2,0,E1"), "book.csv:3: Expected `int` >= 1"),
        (_edit(0, "plot,row,rep,entry"), "book.csv:1: no column column"),
        ("", "book.csv: empty, expected a header line"),
    ],
)
def test_book_errors_are_one_line_naming_the_files(tmp_path: Path, csv: str, needle: str) -> None:
    assert needle in _one_line_error(_toml(tmp_path, csv=csv), tmp_path / "book.csv")


def test_a_missing_or_escaping_csv_is_refused(tmp_path: Path) -> None:
    path = _toml(tmp_path, 'field_book = "nosuch.csv"\n')
    assert "nosuch.csv: cannot read" in _one_line_error(path, tmp_path / "nosuch.csv")
    (tmp_path / "dir.csv").mkdir()
    path.write_text(SMALL + 'field_book = "dir.csv"\n')
    assert "not a regular file" in _one_line_error(path)
    inner = tmp_path / "inner"
    inner.mkdir()
    (tmp_path / "book.csv").write_text(GOOD_CSV)
    (inner / "f.toml").write_text(SMALL + 'field_book = "../book.csv"\n')
    assert "outside the field file's folder" in _one_line_error(inner / "f.toml")


def test_a_book_still_naming_a_csv_is_refused_by_check() -> None:
    layout = msgspec.toml.decode(SMALL + 'field_book = "b.csv"\n', type=FieldLayout)
    with pytest.raises(FieldError, match=r"'b\.csv' is a file that was not read"):
        fieldbook.check(layout, build_field(layout), "req")
