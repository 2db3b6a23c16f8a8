"""The pipeline end to end on the paper's fields, and the plan files."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import msgspec
import pytest

from common.field import ScannerModel, load_field
from common.messages.plan import PlanOptions, PlanResult
from services.planner.compare import lengths_by_nav
from services.planner.core import plan
from services.planner.outputs import write_all


@pytest.mark.parametrize(("name", "count"), [("engr", 11), ("spl", 7)])
def test_plan_paper_fields(name: str, count: int, tmp_path: Path):
    layout, field = load_field(name)
    progress: list[tuple[int, int]] = []
    res = plan(
        layout,
        ScannerModel(),
        PlanOptions(nav="aha"),
        progress=lambda d, n: progress.append((d, n)),
    )
    assert progress[-1] == (77, 77)
    assert res.cover.count == count and res.cover.status == "optimal"
    assert res.cover.greedy_count >= res.cover.count
    assert res.cover.cells_covered == res.cover.cells_coverable == field.n_cells
    assert res.tour.order[0] == res.tour.order[-1] == 0
    assert sorted(res.tour.order[1:-1]) == sorted(res.selected)
    assert res.tour.status == "optimal"
    assert res.tour.length <= res.tour.nn_length + 1e-9
    # the paper's comparison of navigation modes, beside the plan
    by_nav = lengths_by_nav(field, res)
    assert by_nav["br"] <= by_nav["aha"] + 1e-9 and by_nav[res.tour.nav] == pytest.approx(
        res.tour.length
    )
    assert by_nav["lanes"] == pytest.approx(by_nav["aha"])
    assert set(res.timings) == {"field", "visibility", "cover", "tour", "legs"}

    files = write_all(res, tmp_path)
    back = msgspec.json.decode(files["plan.json"].read_bytes(), type=PlanResult)
    assert back.tour.order == res.tour.order and back.legs == res.legs
    geo = json.loads(files["plan.geojson"].read_text())
    kinds = [f["properties"]["kind"] for f in geo["features"]]
    assert kinds.count("plot") == 60 and kinds.count("candidate") == 77
    assert kinds.count("route") == 1 and "frame" not in geo  # georeferenced: WGS84
    lon, lat = geo["features"][0]["geometry"]["coordinates"][0][0]
    assert lat == pytest.approx(33.717, abs=0.01) and lon == pytest.approx(-83.308, abs=0.01)
    with files["waypoints.csv"].open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(res.legs)
    assert files["plan.png"].read_bytes()[:4] == b"\x89PNG"


def test_plan_br_greedy_grid_and_options_from_toml():
    opts = msgspec.toml.decode(
        b'nav = "br"\ncover = "greedy"\nvisibility = "grid"\ngrid_step_deg = 1.0\n',
        type=PlanOptions,
    )
    layout, _ = load_field("spl")
    res = plan(layout, ScannerModel(), opts)
    assert res.cover.method == "greedy" and res.cover.gap is None
    assert res.visibility.mode == "grid" and res.visibility.rays == 77 * 151 * 360
    assert res.tour.nav == "br"
    with pytest.raises(msgspec.ValidationError, match="coverage_target"):
        msgspec.toml.decode(b"coverage_target = 1.5\n", type=PlanOptions)
    with pytest.raises(msgspec.ValidationError, match="unknown field `navv`"):
        msgspec.toml.decode(b'navv = "br"\n', type=PlanOptions)


def test_plan_geojson_field_not_georeferenced_output(tmp_path: Path):
    layout, field = load_field("example_plots")
    res = plan(layout, ScannerModel(), PlanOptions(nav="lanes"), field=field)
    assert res.cover.cells_covered == res.cover.cells_coverable
    plain = msgspec.structs.replace(
        res, layout=msgspec.structs.replace(res.layout, origin_lat=None, origin_lon=None)
    )
    files = write_all(plain, tmp_path)
    assert json.loads(files["plan.geojson"].read_text())["frame"] == "field"
