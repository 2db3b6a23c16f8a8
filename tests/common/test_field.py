"""The field model: shipped fields, candidate numbering, loaders and their errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from common.clock import SimClock, WallClock
from common.field import FieldError, FieldLayout, build_field, load_field
from common.field_geojson import (
    DEFAULT_ORIGIN,
    default_origin_note,
    field_frame,
    field_to_wgs84,
    load_frame,
    placed,
)
from tests.conftest import REPO

NO_ORIGIN = REPO / "tests" / "data" / "no_origin.toml"


@pytest.mark.parametrize(("name", "length", "width"), [("engr", 30.0, 20.0), ("spl", 20.0, 20.0)])
def test_paper_fields_have_77_candidates_and_stated_size(name: str, length: float, width: float):
    _, field = load_field(name)
    assert field.n_candidates == 77
    assert field.n_plots == 60
    assert field.bounds.tolist() == pytest.approx([0, 0, length, width])
    # ids r * 7 + c + 1: r row-gap lane from the bottom, c cross lane from the left
    assert field.cand_ids.tolist() == list(range(1, 78))
    for k in range(77):
        r, c = field.cand_row_lane[k], field.cand_cross_lane[k]
        assert field.cand_ids[k] == 7 * r + c + 1
        assert field.cand_xy[k].tolist() == [field.cross_lanes_x[c], field.row_lanes_y[r]]
    # the paper's Origin: bottom-right corner
    assert field.origin_xy.tolist() == [field.cross_lanes_x[-1], field.row_lanes_y[0]]


def test_engr_cells_match_the_paper():
    _, field = load_field("engr")
    # 3 x 1 x 1.9 m plots in 0.5 x 0.5 x 0.33 m voxels: 72 cells each (paper, section 5)
    assert (field.cell_dims.prod(axis=1) == 72).all()
    assert field.n_cells == 60 * 72
    sizes = field.cell_boxes[:, 3:] - field.cell_boxes[:, :3]
    assert np.allclose(sizes, [0.5, 0.5, 1.9 / 6])


def test_paper_example_plot_has_36_cells():
    layout = FieldLayout(
        rows=1,
        plots_per_row=1,
        plot_length=3,
        plot_width=1,
        plot_height=1,
        row_spacing=1,
        alley_width=1,
        headland_width=1,
    )
    assert build_field(layout).n_cells == 36


def test_clearance_rules():
    base = {
        "rows": 2,
        "plots_per_row": 3,
        "plot_length": 2.0,
        "plot_width": 1.0,
        "plot_height": 1.0,
        "row_spacing": 0.8,
        "alley_width": 1.5,
        "headland_width": 2.0,
    }
    assert build_field(FieldLayout(**base)).n_candidates == 3 * 4  # type: ignore[arg-type]
    # 0.5 m lanes: intersections are 0.35 m from the plot corners, inside the 0.6 m
    # minimum scan distance
    narrow = {**base, "row_spacing": 0.5, "alley_width": 0.5}
    assert build_field(FieldLayout(**narrow)).n_candidates == 0  # type: ignore[arg-type]
    # a 2 m x 2 m robot fits in neither the 1.5 m alleys nor the 0.8 m row gaps
    wide = {**base, "robot_half_width": 1.0, "robot_half_length": 1.0}
    assert build_field(FieldLayout(**wide)).n_candidates == 0  # type: ignore[arg-type]


def _one_line_error(path: Path) -> str:
    with pytest.raises(FieldError) as info:
        load_field(path)
    msg = str(info.value)
    assert "\n" not in msg
    assert str(path) in msg
    return msg


def test_toml_typo_is_one_clear_error(tmp_path: Path):
    text = (Path(__file__).parents[2] / "common/fields/engr.toml").read_text()
    bad = tmp_path / "typo.toml"
    bad.write_text(text.replace("alley_width", "aley_width"))
    assert "aley_width" in _one_line_error(bad)


def test_negative_width_is_one_clear_error(tmp_path: Path):
    text = (Path(__file__).parents[2] / "common/fields/engr.toml").read_text()
    bad = tmp_path / "neg.toml"
    bad.write_text(text.replace("plot_width = 1.0", "plot_width = -1.0"))
    msg = _one_line_error(bad)
    assert "plot_width" in msg and "> 0" in msg


def test_headland_too_narrow_for_its_lane(tmp_path: Path):
    text = (Path(__file__).parents[2] / "common/fields/engr.toml").read_text()
    bad = tmp_path / "headland.toml"
    bad.write_text(text.replace("headland_width = 2.25", "headland_width = 0.2"))
    assert "headland_width=0.2" in _one_line_error(bad)


@pytest.mark.parametrize(
    ("content", "needle"),
    [
        ("{not json", "malformed"),
        (
            '{"type": "FeatureCollection", "features": [{"type": "Feature", '
            '"geometry": {"type": "Point", "coordinates": [1, 2]}}]}',
            "Polygon",
        ),
        ('{"type": "FeatureCollection", "features": []}', "no plot polygons"),
        (
            '{"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": '
            '{"type": "Polygon", "coordinates": [[[0, 0], [1, 0]]]}}]}',
            "at least 3 corners",
        ),
    ],
)
def test_malformed_geojson_is_one_clear_error(tmp_path: Path, content: str, needle: str):
    bad = tmp_path / "bad.geojson"
    bad.write_text(content)
    assert needle in _one_line_error(bad)


def test_rotated_polygon_is_rejected(tmp_path: Path):
    doc = json.loads(
        (Path(__file__).parents[2] / "common/fields/example_plots.geojson").read_text()
    )
    doc["phenorover"]["row_bearing_deg"] = 45.0  # the plots were laid out at 30 deg
    bad = tmp_path / "rot.geojson"
    bad.write_text(json.dumps(doc))
    assert "not an axis-aligned rectangle" in _one_line_error(bad)


def test_unknown_example_lists_the_examples():
    with pytest.raises(FieldError, match=r"examples: .*engr"):
        load_field("nosuchfield")


def test_geojson_example_round_trips_the_layout_it_was_made_from():
    layout, field = load_field("example_plots")
    assert (layout.rows, layout.plots_per_row) == (3, 4)
    assert layout.plot_length == pytest.approx(2.0, abs=1e-3)
    assert layout.row_spacing == pytest.approx(0.8, abs=1e-3)
    assert layout.origin_lat == pytest.approx(33.7171, abs=1e-8)
    assert layout.origin_lon == pytest.approx(-83.3081, abs=1e-8)
    assert field.plot_boxes[0].tolist() == pytest.approx([2.0, 1.5, 0, 4.0, 2.5, 1.4], abs=1e-3)
    assert field.plot_boxes[1, 5] == 1.2  # no height property: the collection default
    assert field.n_candidates == 4 * 5


@settings(max_examples=30, deadline=None)
@given(
    x=st.floats(-500, 500),
    y=st.floats(-500, 500),
    bearing=st.floats(-360, 360),
)
def test_field_wgs84_round_trip(x: float, y: float, bearing: float):
    layout = FieldLayout(
        rows=1,
        plots_per_row=1,
        plot_length=1,
        plot_width=1,
        plot_height=1,
        row_spacing=1,
        alley_width=1,
        headland_width=1,
        origin_lat=33.7,
        origin_lon=-83.3,
        row_bearing_deg=bearing,
    )
    lonlat = field_to_wgs84(layout, np.array([[x, y]]))
    fx, fy, _ = field_frame(layout).wgs84_to_field(lonlat[0, 1], lonlat[0, 0])
    assert float(fx) == pytest.approx(x, abs=1e-6)
    assert float(fy) == pytest.approx(y, abs=1e-6)


def test_a_simulated_world_places_a_field_without_origin_at_engrs() -> None:
    engr, _ = load_field("engr")
    assert (engr.origin_lat, engr.origin_lon) == DEFAULT_ORIGIN  # somewhere real
    layout, _ = load_field(NO_ORIGIN)
    assert not layout.georeferenced
    for clock in ("sim", SimClock()):  # a manifest's clock, or a service's
        at = placed(layout, NO_ORIGIN, clock)
        assert (at.origin_lat, at.origin_lon) == DEFAULT_ORIGIN
        assert (at.origin_alt, at.row_bearing_deg) == (layout.origin_alt, layout.row_bearing_deg)
    # every service that loads the frame on the sim clock gets the same one
    frame = load_frame(str(NO_ORIGIN), SimClock())
    assert frame.origin == (*DEFAULT_ORIGIN, 0.0)
    assert frame.field_to_wgs84(0.0, 0.0)[:2] == pytest.approx(DEFAULT_ORIGIN, abs=1e-9)
    note = default_origin_note(layout)
    assert note.startswith("field 'h3' has no georeference: placed at the default origin")
    assert "33.717028 N, 83.308083 W" in note and "simulation only" in note
    # a field with its own origin keeps it, simulated or not
    assert placed(engr, "engr", "sim") is engr


@pytest.mark.parametrize("clock", [None, "wall", WallClock()])
def test_a_real_deployment_refuses_a_field_without_origin_naming_file_and_keys(
    clock: object,
) -> None:
    with pytest.raises(FieldError) as err:
        load_frame(str(NO_ORIGIN), clock)
    text = str(err.value)
    assert "\n" not in text and text.startswith(f"{NO_ORIGIN}: field 'h3' has no georeference")
    assert "origin_lat, origin_lon are not set" in text


def test_half_an_origin_is_refused_even_in_simulation(tmp_path: Path) -> None:
    half = tmp_path / "half.toml"
    half.write_text(NO_ORIGIN.read_text() + "origin_lat = 40.0\n")
    layout, _ = load_field(half)
    with pytest.raises(
        FieldError, match=r"half\.toml: field 'h3': origin_lat is set but origin_lon"
    ):
        placed(layout, half, "sim")
