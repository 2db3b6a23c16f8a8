"""The crop model from canopy points, the field as measured, and planning on it."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from common import cropmodel
from common.cropmodel import CropModel, CropModelError, crop_model
from common.field import Field, FieldLayout, load_field
from common.messages.plan import PlanOptions
from services.planner.cli import add_arguments, cmd_plan
from services.planner.core import plan
from services.planner.measured import (
    compare,
    measured_field,
    plan_measured,
    target_cells,
)

TINY = Path(__file__).parents[1] / "data" / "tiny.toml"
F64 = npt.NDArray[np.float64]
OPTS = PlanOptions(cover="greedy")


@pytest.fixture(scope="module")
def tiny() -> tuple[FieldLayout, Field]:
    return load_field(TINY)


def _fill(lo: tuple[float, float], hi: tuple[float, float], top: float) -> tuple[F64, F64]:
    """Canopy points on a 5 cm grid over [lo, hi], heights spread up to ``top``."""
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0], 0.05), np.arange(lo[1], hi[1], 0.05))
    xy = np.column_stack([gx.ravel(), gy.ravel()]) + 0.025
    h = np.linspace(0.1, top, len(xy))
    return xy, np.random.default_rng(0).permutation(h)


def _survey(field: Field, tops: list[float], gap_plot: int = 2) -> tuple[F64, F64]:
    """Every plot filled to its ``tops`` (0: none); ``gap_plot`` has no plants in its
    x 1.0-2.0 m; ground points everywhere."""
    parts = []
    for p, top in enumerate(tops):
        if top <= 0:
            continue
        b = field.plot_boxes[p]
        if p == gap_plot:
            parts.append(_fill((b[0], b[1]), (b[0] + 1.0, b[4]), top))
            parts.append(_fill((b[0] + 2.0, b[1]), (b[3], b[4]), top))
        else:
            parts.append(_fill((b[0], b[1]), (b[3], b[4]), top))
    ground = _fill(tuple(field.bounds[:2]), tuple(field.bounds[2:]), 0.01)
    parts.append((ground[0], np.zeros(len(ground[0]))))
    return np.vstack([a for a, _ in parts]), np.concatenate([b for _, b in parts])


def test_crop_model_heights_gaps_and_empty(tiny: tuple[FieldLayout, Field]) -> None:
    layout, field = tiny
    xy, h = _survey(field, [1.0, 1.5, 1.2, 0.8, 1.0, 0.0])
    m = crop_model(xy, h, field, layout, date="2026-07-20")
    assert m.field == "tiny" and m.date == "2026-07-20" and m.cell == (0.5, 0.5)
    boxes = m.boxes()
    assert boxes[1, 4] == pytest.approx(1.5, abs=0.02)
    assert boxes[3, 4] == pytest.approx(0.8, abs=0.02)
    nominal = field.plot_boxes
    assert np.allclose(boxes[0, :4], nominal[0, [0, 1, 3, 4]], atol=0.05)
    full = len(m.plots[0].columns)
    assert full == 12 and m.plots[0].grid == (6, 2)
    assert len(m.plots[2].columns) == full - 4  # the 1 m gap: two columns of two
    assert m.plots[5].box is None and m.plots[5].columns == () and m.plots[5].points == 0
    assert np.isnan(boxes[5]).all()


def test_crop_model_lean_is_clipped_before_the_next_plot(
    tiny: tuple[FieldLayout, Field],
) -> None:
    layout, field = tiny
    b0, b1 = field.plot_boxes[0], field.plot_boxes[1]
    xy, h = _survey(field, [1.0] * 6)
    # plants of plot 0 leaning 0.2 m into the alley towards plot 1
    lean, lh = _fill((b0[3], b0[1] + 0.3), (b0[3] + 0.2, b0[1] + 0.6), 0.9)
    m = crop_model(np.vstack([xy, lean]), np.concatenate([h, lh]), field, layout)
    assert m.boxes()[0, 2] == pytest.approx(b0[3] + 0.2, abs=0.03)
    assert m.plots[0].points > m.plots[3].points
    # a cluster across the whole alley, with a margin wider than it: plot 0 takes the
    # half nearer to it, never reaching plot 1's nominal box
    across, ah = _fill((b0[3], b0[1]), (b1[0], b0[4]), 0.9)
    m = crop_model(np.vstack([xy, across]), np.concatenate([h, ah]), field, layout, margin=1.0)
    mid = (b0[3] + b1[0]) / 2
    assert mid - 0.05 < m.boxes()[0, 2] <= mid < b1[0]
    assert m.boxes()[1, 0] >= mid
    # beyond the margin nothing belongs to any plot
    far, fh = _fill((b0[0], b0[1] - 0.7), (b0[3], b0[1] - 0.5), 0.9)
    m = crop_model(np.vstack([xy, far]), np.concatenate([h, fh]), field, layout)
    assert m.boxes()[0, 1] == pytest.approx(b0[1], abs=0.05)


def test_crop_model_rejects_bad_input(tiny: tuple[FieldLayout, Field]) -> None:
    layout, field = tiny
    with pytest.raises(ValueError, match="expected xy"):
        crop_model(np.zeros((3, 3)), np.zeros(3), field, layout)
    m = crop_model(np.zeros((0, 2)), np.zeros(0), field, layout)
    assert all(pc.box is None for pc in m.plots)


def test_write_read_round_trip_and_errors(tiny: tuple[FieldLayout, Field], tmp_path: Path) -> None:
    layout, field = tiny
    xy, h = _survey(field, [1.0, 1.5, 1.2, 0.8, 1.0, 0.0])
    m = crop_model(xy, h, field, layout)
    path = tmp_path / "crop.json"
    cropmodel.write(path, m)
    assert cropmodel.read(path, field) == m
    assert [p.name for p in tmp_path.iterdir()] == ["crop.json"]  # no temp file left

    with pytest.raises(CropModelError, match="no crop model"):
        cropmodel.read(tmp_path / "none.json")
    (tmp_path / "bad.json").write_text('{"field": "tiny"')
    with pytest.raises(CropModelError, match="not a crop model"):
        cropmodel.read(tmp_path / "bad.json")
    _, trial = load_field("trial")
    with pytest.raises(CropModelError, match="not of field 'trial'") as exc:
        cropmodel.read(path, trial)
    assert "\n" not in str(exc.value)
    raw = json.loads(path.read_text())
    raw["plots"][0]["columns"][0] = 99
    (tmp_path / "range.json").write_text(json.dumps(raw))
    with pytest.raises(CropModelError, match="outside the plot's 12 columns"):
        cropmodel.read(tmp_path / "range.json")


def _model(field: Field, layout: FieldLayout, tops: list[float], gap: int = 2) -> CropModel:
    xy, h = _survey(field, tops, gap_plot=gap)
    return crop_model(xy, h, field, layout)


def test_measured_field_lower_boxes_fewer_targets(tiny: tuple[FieldLayout, Field]) -> None:
    layout, field = tiny
    m = _model(field, layout, [1.0, 1.5, 1.2, 0.8, 1.0, 0.0])
    _, mf = measured_field(layout, field, m)
    assert np.all(mf.plot_boxes[:5, 5] < field.plot_boxes[:5, 5])
    assert mf.plot_boxes[1, 5] == pytest.approx(1.5, abs=0.02)
    assert mf.plot_boxes[5, 5] == pytest.approx(0.05)  # no canopy: a bare footprint
    assert mf.n_cells < field.n_cells
    targets = target_cells(field, mf, m)
    per_plot = np.bincount(mf.cell_plot[targets], minlength=6)
    cells = np.bincount(mf.cell_plot, minlength=6)
    assert per_plot[5] == 0 and per_plot[0] == cells[0]
    assert per_plot[2] == cells[2] - 2 * 2 * mf.cell_dims[2, 2]  # the gap's columns
    # the same crop without the gap has more targets
    m_full = _model(field, layout, [1.0, 1.5, 1.2, 0.8, 1.0, 0.0], gap=-1)
    assert target_cells(field, mf, m_full).sum() > targets.sum()


def test_plan_on_the_measured_crop_and_compare(tiny: tuple[FieldLayout, Field]) -> None:
    layout, field = tiny
    m = _model(field, layout, [0.6, 1.5, 0.5, 1.5, 0.6, 0.0])
    nominal = plan(layout, None, OPTS, field=field)
    measured = plan_measured(layout, field, m, None, OPTS)
    # planned on the measured boxes, keeping the field's own as its footprints
    assert not np.allclose(measured.plot_boxes.numpy().reshape(-1, 6), field.plot_boxes)
    assert np.array_equal(measured.plot_footprints(), field.plot_boxes)
    assert np.array_equal(nominal.plot_footprints(), field.plot_boxes)
    assert measured.cover.cells_total < nominal.cover.cells_total
    assert measured.cover.cells_covered == measured.cover.cells_coverable
    assert measured.cell_views is not None
    text = compare(nominal, measured)
    a, b = set(nominal.selected), set(measured.selected)
    for line, ids in (("kept", a & b), ("added", b - a), ("removed", a - b)):
        row = next(r for r in text.splitlines() if r.startswith(line))
        assert f"  {len(ids)}" in row and all(str(i) in row for i in ids)
    assert "target cells covered" in text


def _cli(argv: list[str]) -> int:
    p = argparse.ArgumentParser()
    add_arguments(p)
    return cmd_plan(p.parse_args(argv))


def test_cli_from_survey(
    tiny: tuple[FieldLayout, Field], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    layout, field = tiny
    run = tmp_path / "run"
    run.mkdir()
    assert _cli([str(TINY), "--from-survey", str(run), "--cover", "greedy"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "run `phenorover traits" in err

    trial_layout, trial = load_field("trial")
    cropmodel.write(
        run / "crop.json", crop_model(np.zeros((0, 2)), np.zeros(0), trial, trial_layout)
    )
    assert _cli([str(TINY), "--from-survey", str(run)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not of field 'tiny'" in err

    cropmodel.write(run / "crop.json", _model(field, layout, [1.0, 1.5, 1.2, 0.8, 1.0, 0.0]))
    out = tmp_path / "plan"
    assert _cli([str(TINY), "--from-survey", str(run), "--cover", "greedy", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "nominal" in text and "measured" in text and "added" in text
    assert (out / "plan.json").is_file()
