from __future__ import annotations

import math
from pathlib import Path

import msgspec
import numpy as np
import pytest

from common.canopy import TRAITS
from common.cropmodel import assign_plots
from common.field import load_field
from common.messages.core import Array
from common.messages.plan import PlanResult
from services.traits.compute import NAMES, NO_POINTS, OCCLUDED, OK, compute_run
from services.traits.config import GroundConfig
from services.traits.ground import GroundModel, fit_ground, lowest_per_cell
from services.traits.run import RunError, load_run, survey_date
from tests.traits.conftest import (
    CANOPIES,
    CREATED_NS,
    TINY,
    Canopy,
    ground_z,
    plan_for,
    synthetic_cloud,
    write_run,
)


def test_assign_plots_matches_a_box_by_box_check() -> None:
    field = load_field(TINY)[1]
    rng = np.random.default_rng(1)
    b = field.bounds
    xy = rng.uniform(b[:2] - 0.5, b[2:] + 0.5, (20_000, 2))
    got = assign_plots(xy, field.plot_boxes, field.plot_row, field.plot_col, 0.0)
    want = np.full(len(xy), -1)
    for k, (x0, y0, _, x1, y1, _) in enumerate(field.plot_boxes):
        inside = (xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)
        want[inside] = k
    np.testing.assert_array_equal(got, want)
    assert (got >= 0).any() and (got < 0).any()


def test_ground_model_is_bilinear_and_exact_on_a_plane() -> None:
    x = 0.25 * (np.arange(40) + 0.5)
    y = 0.25 * (np.arange(20) + 0.5)
    z = 3.0 + 0.1 * x[None, :] - 0.05 * y[:, None]
    g = GroundModel(0.0, 0.0, 0.25, z, np.ones(z.shape, bool), np.ones(z.shape, np.int64))
    rng = np.random.default_rng(2)
    px, py = rng.uniform(0.2, 9.8, 500), rng.uniform(0.2, 4.8, 500)
    np.testing.assert_allclose(g.height(px, py), 3.0 + 0.1 * px - 0.05 * py, atol=1e-9)
    assert g.height(np.zeros((2, 3)), np.zeros((2, 3))).shape == (2, 3)


def test_stable_mask_keeps_lanes_only() -> None:
    z = np.zeros((20, 40))
    measured = np.ones(z.shape, bool)
    measured[0, 0] = False
    g = GroundModel(0.0, 0.0, 0.25, z, measured, measured.astype(np.int64))
    box = np.array([[2.0, 1.0, 0.0, 5.0, 2.0, 1.0]])
    m = g.stable_mask(box, margin=0.5)
    cx, cy = g.centres()
    near = (
        (cx[None, :] + 0.125 > 1.5)
        & (cx[None, :] - 0.125 < 5.5)
        & (cy[:, None] + 0.125 > 0.5)
        & (cy[:, None] - 0.125 < 2.5)
    )
    assert not m[near].any()
    assert m[~near & measured].all()
    assert not m[0, 0]


def test_lowest_per_cell_keeps_the_lowest_point() -> None:
    pts = np.array([[0.01, 0.01, 1.0], [0.02, 0.03, 0.5], [0.52, 0.5, 2.0], [0.55, 0.5, 3.0]])
    low = lowest_per_cell(pts, 0.1)
    assert sorted(low[:, 2].tolist()) == [0.5, 2.0]


@pytest.mark.parametrize("slope", [(0.0, 0.0), (0.06, -0.03)])
def test_ground_under_canopies_follows_the_slope(slope: tuple[float, float]) -> None:
    field = load_field(TINY)[1]
    xyz = synthetic_cloud(field, [Canopy(0.9)] * 6, slope=slope, spacing=0.03, seed=4)
    g = fit_ground(xyz, field.bounds[[0, 1, 2, 3]], GroundConfig())
    b = field.plot_boxes
    centres = np.column_stack([(b[:, 0] + b[:, 3]) / 2, (b[:, 1] + b[:, 4]) / 2])
    # the ground under every (fully covered) plot, from the lanes around it
    err = g.height(centres[:, 0], centres[:, 1]) - ground_z(centres, slope)
    assert np.abs(err).max() < 0.01


def test_traits_on_sloped_ground(sloped_run: Path) -> None:
    rt = compute_run(sloped_run)
    t = rt.table
    assert t.values.shape == (6, len(TRAITS))
    assert t.quality == [OK, OK, NO_POINTS, OK, OCCLUDED, OK]
    for k, c in enumerate(CANOPIES):
        if c.height is None:
            continue
        assert t.column("height")[k] == pytest.approx(c.height, abs=0.015), k
        assert t.column("height_p50")[k] == pytest.approx(c.height, abs=0.015), k
        if c.seen == 1.0:
            # the canopy's walls add at most one 5 cm cell row across a 1 m plot
            assert t.column("cover")[k] == pytest.approx(c.cover, abs=0.06), k
            assert t.column("seen")[k] > 0.95
    # a plot of 0.6 m canopy over a 3 x 1 m footprint: its hull from 5 cm up (lower
    # points are ground) ~ 3 x 1 x 0.55
    assert t.column("volume_hull")[0] == pytest.approx(1.65, rel=0.03)
    assert t.column("seen")[4] == pytest.approx(0.4, abs=0.05)


def test_a_plot_with_no_points_has_nan_traits(sloped_run: Path) -> None:
    t = compute_run(sloped_run).table
    row = dict(zip(NAMES, t.values[2], strict=True))
    assert t.quality[2] == NO_POINTS
    assert row["points"] == 0 and row["seen"] == 0
    shape = [n for n in NAMES if n not in ("points", "seen")]
    assert all(math.isnan(row[n]) for n in shape)


def test_run_records_date_and_field_book(sloped_run: Path) -> None:
    rt = compute_run(sloped_run)
    assert rt.date == "2024-06-03" and "mission" in rt.date_source
    assert [r.plot for r in rt.records] == [str(p) for p in range(101, 107)]
    assert rt.table.records[1].entry == "G2" and rt.table.records[4].rep == 2
    assert compute_run(sloped_run, date="2024-07-01").table.date == "2024-07-01"


def test_simulated_run_takes_the_manifest_trial_date(tmp_path: Path) -> None:
    (tmp_path / "manifest.toml").write_text("[services.sim.world.trial]\ndate = 2025-05-20\n")
    assert survey_date(tmp_path, 5 * 10**9, None)[0] == "2025-05-20"
    assert survey_date(tmp_path, CREATED_NS, None)[0] == "2024-06-03"
    (tmp_path / "manifest.toml").write_text("[services.sim]\nbackend = 'x'\n")
    assert survey_date(tmp_path, 5 * 10**9, None) == ("", "")
    with pytest.raises(RunError, match="--date"):
        survey_date(tmp_path, 0, "June 3rd")


def test_plot_boxes_neither_layout_nor_field_file_are_refused(
    tiny_plan: PlanResult, tmp_path: Path
) -> None:
    pr = plan_for(tiny_plan, load_field(TINY)[0])
    moved = np.asarray(pr.plot_boxes.numpy()).reshape(-1, 6).copy()
    moved[0, [0, 3]] += 0.3  # a plot that is not where the layout puts it
    bad = msgspec.structs.replace(pr, plot_boxes=Array.of(moved))
    run = write_run(tmp_path / "run", bad, np.array([[1.0, 1.0, 0.0]]))
    with pytest.raises(RunError, match="plot boxes"):
        load_run(run)


def test_a_plan_on_the_measured_crop_is_cut_by_the_field_books_plots(
    tiny_plan: PlanResult, tmp_path: Path
) -> None:
    # `phenorover plan --from-survey` plans on the measured canopy, which leans past
    # the footprints; the survey flown on it is still measured plot by plot
    layout, field = load_field(TINY)
    pr = plan_for(tiny_plan, layout)
    canopy = field.plot_boxes.copy()
    canopy[:, [1, 4]] += [-0.2, 0.2]
    measured = msgspec.structs.replace(
        pr, plot_boxes=Array.of(canopy), footprints=Array.of(field.plot_boxes)
    )
    back = msgspec.json.decode(msgspec.json.encode(measured), type=PlanResult)
    assert np.array_equal(back.plot_footprints(), field.plot_boxes)
    run = write_run(tmp_path / "run", measured, np.array([[1.0, 1.0, 0.0]]))
    assert np.array_equal(load_run(run).field.plot_boxes, field.plot_boxes)
    # without the footprints the same boxes are refused, as any other
    run2 = write_run(tmp_path / "run2", msgspec.structs.replace(measured, footprints=None), None)
    with pytest.raises(RunError, match="plot boxes"):
        load_run(run2)
    # footprints that are not boxes: one line, not a traceback
    bad = Array(dtype="<f8", shape=(7,), data=np.zeros(7).tobytes())
    run3 = write_run(tmp_path / "run3", msgspec.structs.replace(measured, footprints=bad), None)
    with pytest.raises(RunError, match="plot boxes"):
        load_run(run3)
