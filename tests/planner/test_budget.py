"""Bounds on fields: the schema's limits (one line each, before any large allocation),
the memory-bounded clearance test, the planner's budget (CLI exit 2) and the folders
a planner service may read field files from."""

from __future__ import annotations

import json
import tracemalloc
from pathlib import Path

import msgspec
import numpy as np
import pytest

from common.field import (
    FIELDS_DIR,
    FieldError,
    FieldLayout,
    _clear,
    build_field,
    load_field,
)
from common.field_geojson import field_from_geojson
from common.field_model import MAX_PLOTS
from phenorover.cli import main
from services.planner.budget import OverBudget, PlanBudget, check
from services.planner.request import confine

LANES = (
    "plot_length = 3.0\nplot_width = 1.0\nplot_height = 1.9\nrow_spacing = 0.8\n"
    "alley_width = 1.5\nheadland_width = 2.25\nedge_width = 1.4\n"
)


def layout(rows: int, plots: int, **kw: float) -> FieldLayout:
    base = dict(plot_length=3.0, plot_width=1.0, plot_height=1.9, row_spacing=0.8)
    base |= dict(alley_width=1.5, headland_width=2.25, edge_width=1.4) | kw
    raw = {"name": "f", "rows": rows, "plots_per_row": plots, **base}
    return msgspec.convert(raw, FieldLayout)


def test_ten_thousand_rows_is_one_line_not_a_traceback(tmp_path: Path) -> None:
    f = tmp_path / "huge.toml"
    f.write_text(f'name = "huge"\nrows = 10000\nplots_per_row = 6\n{LANES}')
    with pytest.raises(FieldError, match=r"huge\.toml: Expected `int` <= 1000 - at `\$\.rows`"):
        load_field(f)


@pytest.mark.parametrize(
    ("kw", "message"),
    [
        (dict(rows=500, plots=500), r"500 x 500 = 250,000 plots, more than the 20,000"),
        (dict(rows=10, plots=10, plot_length=1000.0), r"10,018\.0 m x 20\.0 m, more than 5,000 m"),
        (dict(rows=10, plots=10, voxel_x=0.01, voxel_z=0.01), r"voxel cells .* more than the"),
    ],
)
def test_absurd_fields_are_refused_before_allocating(kw: dict[str, float], message: str) -> None:
    rows, plots = int(kw.pop("rows")), int(kw.pop("plots"))
    tracing = tracemalloc.is_tracing()  # someone's (PYTHONTRACEMALLOC): left on
    tracemalloc.start()
    tracemalloc.reset_peak()
    try:
        with pytest.raises(FieldError, match=message):
            build_field(layout(rows, plots, **kw))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        if not tracing:
            tracemalloc.stop()
    # refused from the layout's counts, before any array: a field of 40 x 40 plots
    # takes 13 MB to build, these would take gigabytes
    assert peak < 1e6, peak


def test_a_field_file_must_be_a_regular_file_of_sane_size(tmp_path: Path) -> None:
    with pytest.raises(FieldError, match=r"^/dev/zero: not a regular file$"):
        load_field("/dev/zero")  # would never end
    big = tmp_path / "big.geojson"
    with big.open("wb") as f:
        f.truncate(65 << 20)
    with pytest.raises(FieldError, match=r"big\.geojson: 68,157,440 bytes, more than"):
        load_field(big)


def test_too_many_geojson_plots_are_refused_before_converting_them() -> None:
    ring = [[0.0, 0.0], [1e-5, 0.0], [1e-5, 1e-5], [0.0, 1e-5], [0.0, 0.0]]
    feat = {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [ring]}}
    doc = {"type": "FeatureCollection", "features": [feat] * (MAX_PLOTS + 1)}
    with pytest.raises(FieldError, match=r"x\.geojson: 20,001 plot polygons, more than"):
        field_from_geojson(json.dumps(doc).encode(), "x.geojson")


def _clear_dense(lay: FieldLayout, xy: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """The clearance rule over all candidate x plot pairs at once (the old way)."""
    lo, hi, p = boxes[None, :, 0:2], boxes[None, :, 3:5], xy[:, None, :]
    gap = np.maximum(np.maximum(lo - p, p - hi), 0.0)
    far = np.hypot(gap[..., 0], gap[..., 1]).min(axis=1) >= lay.min_scan_distance
    hl, hw = lay.robot_half_length, lay.robot_half_width
    fits = np.zeros(len(xy), dtype=bool)
    for ax, ay in ((hl, hw), (hw, hl)):
        fits |= ~((gap[..., 0] < ax) & (gap[..., 1] < ay)).any(axis=1)
    return far & fits


@pytest.mark.parametrize(
    "lay",
    [
        load_field("engr")[0],
        load_field("spl")[0],
        layout(7, 9, min_scan_distance=1.2),
        layout(12, 5, row_spacing=0.5, alley_width=0.9, edge_width=0.5, headland_width=0.5),
    ],
)
def test_chunked_clearance_equals_the_dense_rule(lay: FieldLayout) -> None:
    f = build_field(lay)
    rng = np.random.default_rng(3)
    lo, hi = f.bounds[:2], f.bounds[2:]
    xy = np.vstack([rng.uniform(lo, hi, (400, 2)), f.cand_xy])
    assert np.array_equal(
        _clear(lay, xy, f.plot_boxes, chunk=16), _clear_dense(lay, xy, f.plot_boxes)
    )


def test_budget_takes_the_papers_fields_and_100_by_100_and_refuses_140_by_140() -> None:
    b = PlanBudget()
    for name in ("engr", "spl"):
        check(load_field(name)[1], b)
    # a candidate reaches the plots within the scanner's range, not the whole field
    assert 1e8 < check(build_field(layout(40, 50)), b).pairs < 2091 * 144_000
    assert 1e9 < check(build_field(layout(100, 100)), b).pairs < 2e9
    with pytest.raises(OverBudget, match=r"1,411,200 cells, 19,881 candidates, about 2\.\de\+09"):
        check(build_field(layout(140, 140)), b)
    # a shorter range reaches fewer plots
    assert check(build_field(layout(140, 140)), b, reach=30.0).pairs < 1e9


def test_plan_cli_refuses_a_field_beyond_the_budget_with_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    f = tmp_path / "big.toml"
    f.write_text(f'name = "big"\nrows = 140\nplots_per_row = 140\n{LANES}')
    assert main(["plan", str(f), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "budget" in err[0] and "max_cell_candidates" in err[0], err


def test_field_files_are_confined_to_the_allowed_folders(tmp_path: Path) -> None:
    inside = tmp_path / "ok"
    inside.mkdir()
    (inside / "a.toml").write_text("x")
    (inside / "escape.toml").symlink_to(FIELDS_DIR / "spl.toml")
    assert confine(str(inside / "a.toml"), [inside]) == (inside / "a.toml").resolve()
    assert confine("engr", [FIELDS_DIR]) == (FIELDS_DIR / "engr.toml").resolve()
    for name in (str(inside / "escape.toml"), str(inside / ".." / "b.toml"), "/etc/passwd"):
        with pytest.raises(FieldError, match=r"PlanRequest\.name: .* outside the planner's"):
            confine(name, [inside])
    with pytest.raises(FieldError, match="no such field file or example"):
        confine("nosuch", [inside])


def test_budget_is_in_the_planner_config() -> None:
    from services.planner.config import PlannerConfig

    cfg = msgspec.toml.decode(b"[budget]\nmax_cell_candidates = 5\n", type=PlannerConfig)
    assert cfg.budget.max_cell_candidates == 5 and cfg.field_dirs == []


def test_sim_refuses_a_field_nobody_could_plan_before_starting_anything(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    f = tmp_path / "big.toml"
    f.write_text(f'name = "big"\nrows = 140\nplots_per_row = 140\n{LANES}')
    assert main(["sim", "--field", str(f)]) == 2
    assert main(["sim", "--field", str(tmp_path / "none.toml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "budget" in err[0] and "none.toml: cannot read" in err[1], err
