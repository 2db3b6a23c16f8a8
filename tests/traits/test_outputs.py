from __future__ import annotations

import json
from pathlib import Path

import geopandas as gpd
import msgspec
import numpy as np
import pandas as pd
import pytest

from common.canopy import TRAITS, CanopyDefinition
from common.field import load_field
from common.messages.plan import PlanResult
from services.traits.compute import RunTraits, compute_run
from services.traits.config import TraitsConfig
from services.traits.outputs import BOOK, header, write_outputs
from tests.traits.conftest import TINY, Canopy, plan_for, synthetic_cloud, write_run


@pytest.fixture(scope="module")
def written(sloped_run: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[RunTraits, Path]:
    out = tmp_path_factory.mktemp("out")
    rt = compute_run(sloped_run)
    write_outputs(rt, TraitsConfig(), out)
    return rt, out


def test_traits_csv_has_the_field_book_first(written: tuple[RunTraits, Path]) -> None:
    rt, out = written
    d = pd.read_csv(out / "traits.csv", dtype={"plot": str, "entry": str})
    assert list(d.columns[:5]) == list(BOOK)
    assert list(d.columns) == header()
    assert "height (m)" in d.columns and "volume_voxel (m3)" in d.columns
    assert (
        d["plot"].tolist()
        == [r.plot for r in rt.records]
        == ["101", "102", "103", "104", "105", "106"]
    )
    assert d["entry"].tolist() == [r.entry for r in rt.records]
    assert d["rep"].tolist() == [1, 1, 1, 2, 2, 2]
    assert d["row"].tolist() == [1, 1, 1, 2, 2, 2] and d["column"].tolist() == [1, 2, 3] * 2
    np.testing.assert_allclose(d["height (m)"], np.round(rt.table.column("height"), 3))
    assert np.isnan(d.loc[2, "height (m)"]) and d.loc[2, "quality"] == "no points"
    assert (d["date"] == "2024-06-03").all()
    # heights to the millimetre in the file itself
    line = (out / "traits.csv").read_text().splitlines()[1].split(",")
    assert len(line[5].split(".")[1]) == 3


def test_long_csv_lists_every_plot_and_trait_with_its_method(
    written: tuple[RunTraits, Path],
) -> None:
    rt, out = written
    d = pd.read_csv(out / "traits_long.csv", dtype={"plot": str})
    assert list(d.columns) == ["plot", "trait", "value", "unit", "date", "method"]
    assert len(d) == 6 * len(TRAITS)
    h = d[(d["trait"] == "height") & (d["plot"] == "101")].iloc[0]
    assert h.unit == "m" and h.value == pytest.approx(rt.table.column("height")[0], abs=6e-4)
    assert h.method == CanopyDefinition().method("height")
    assert d[(d["trait"] == "height") & (d["plot"] == "103")].value.isna().all()


def test_geojson_is_wgs84_with_plot_ids(written: tuple[RunTraits, Path]) -> None:
    rt, out = written
    g = gpd.read_file(out / "traits.geojson")
    assert g["plot"].tolist() == [r.plot for r in rt.records]
    assert g["entry"].tolist() == [r.entry for r in rt.records]
    assert g.crs is not None and g.crs.to_epsg() == 4326
    lon, lat = g.geometry.iloc[0].exterior.coords[0]
    assert lat == pytest.approx(rt.layout.origin_lat, abs=1e-3)
    assert lon == pytest.approx(rt.layout.origin_lon, abs=1e-3)
    assert g["height"].iloc[0] == pytest.approx(rt.table.column("height")[0], abs=6e-4)
    assert g["quality"].tolist()[2] == "no points"
    raw = json.loads((out / "traits.geojson").read_text())
    assert raw["phenorover"]["units"]["height"] == "m" and "crs_note" not in raw["phenorover"]


def test_fieldmap_png(written: tuple[RunTraits, Path]) -> None:
    _, out = written
    assert (out / "fieldmap.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(out.glob(".*.part*"))


def test_field_without_georeference_stays_in_metres(tiny_plan: PlanResult, tmp_path: Path) -> None:
    layout = msgspec.structs.replace(load_field(TINY)[0], origin_lat=None, origin_lon=None)
    field = load_field(TINY)[1]
    xyz = synthetic_cloud(field, [Canopy(0.5)] * 6, spacing=0.04)
    run = write_run(tmp_path / "run", plan_for(tiny_plan, layout), xyz, created_ns=0)
    rt = compute_run(run)
    write_outputs(rt, TraitsConfig(figures=False), run)
    raw = json.loads((run / "traits.geojson").read_text())
    assert "field-frame metres" in raw["phenorover"]["crs_note"]
    ring = raw["features"][0]["geometry"]["coordinates"][0]
    b = field.plot_boxes[0]
    assert ring[0] == pytest.approx([b[0], b[1]]) and ring[2] == pytest.approx([b[3], b[4]])
    assert raw["features"][0]["properties"]["date"] == ""
    assert not (run / "fieldmap.png").exists()
