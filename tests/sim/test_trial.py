"""The simulated breeding trial: growth to a date, entries, gaps, leans, its truth."""

from __future__ import annotations

import datetime
import functools
import hashlib
import json
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest

from common.field import Field, FieldLayout, build_field, load_field
from common.field_model import PlotRecord
from phenorover.eval.fields import engr_sized
from services.sim.foliage import EMPTY, Foliage, build_foliage
from services.sim.plant_config import FoliageConfig, TrialConfig
from services.sim.plant_truth import plant_truth, write_plant_truth
from services.sim.terrain import Terrain, TerrainConfig, build_terrain
from services.sim.trial import TrialPlan, entry_effects, growth, plan_trial
from services.sim.truth_file import PLANTS_TRUTH
from services.sim.world import World
from services.sim.world_config import TargetConfig, WorldConfig

# sha256 of World(*load_field(name)).foliage.occ, taken on the code before trials
# existed: a field with no entries and no date must grow exactly the same plants
PINNED = {
    "engr": "05305e1671c1ea57243eec4b2cd134f4b8504af58ab4a6cbde2e59871e6edcc2",
    "spl": "3ecd4c6888658aaad3bcc3fcc7b6e5a267e9e547270c776d44aadc34c4d6fc92",
}
PLANTED = datetime.date(2026, 5, 1)
ENTRIES, REPS = 6, 3


def _layout(book: bool = True, planting: datetime.date | None = PLANTED) -> FieldLayout:
    """ENGR's plots, 3 rows (one rep each) x 6 plots (6 entries, shifted per rep)."""
    recs = tuple(
        PlotRecord(
            plot=f"{r}{c:02d}",
            row=r,
            column=c,
            entry=f"G{(c - 1 + 2 * r) % ENTRIES + 1:02d}",
            rep=r,
        )
        for r in range(1, REPS + 1)
        for c in range(1, ENTRIES + 1)
    )
    return msgspec.structs.replace(
        engr_sized(REPS, ENTRIES, "mini"), field_book=recs if book else (), planting_date=planting
    )


@functools.cache
def _mini() -> tuple[FieldLayout, Field, Terrain]:
    layout = _layout()
    field = build_field(layout)
    return layout, field, build_terrain(field.bounds, TerrainConfig(), 0)


@functools.cache
def _plants(cfg: TrialConfig, seed: int = 0) -> tuple[TrialPlan, Foliage]:
    """The mini trial's plan and plants under ``cfg``."""
    layout, field, terrain = _mini()
    plan = plan_trial(layout, field, FoliageConfig(), cfg, seed)
    assert plan is not None
    plans = [p.growth for p in plan.plots]
    return plan, build_foliage(field.plot_boxes, terrain, FoliageConfig(), seed, plans)


@functools.cache
def _grow(cfg: TrialConfig) -> tuple[TrialPlan, Foliage, list[dict[str, Any]]]:
    """The mini trial's plan, plants and truth under ``cfg`` (seed 0)."""
    layout, field, terrain = _mini()
    plan, fol = _plants(cfg)
    return plan, fol, plant_truth(layout, field, terrain, fol, plan)


def _at(days: int, **kw: Any) -> TrialConfig:
    return TrialConfig(date=PLANTED + datetime.timedelta(days=days), **kw)


@pytest.mark.parametrize("name", sorted(PINNED))
def test_a_field_without_entries_or_date_grows_as_before(name: str) -> None:
    world = World(*load_field(name))
    assert world.trial is None
    assert hashlib.sha256(world.foliage.occ.tobytes()).hexdigest() == PINNED[name]


def test_growth_is_logistic_in_days_after_planting() -> None:
    sizes = [growth(d) for d in range(0, 150, 10)]
    assert np.all(np.diff(sizes) > 0)
    assert sizes[0] < 0.02 and growth(55) == pytest.approx(0.5) and growth(110) > 0.98
    plan, _, _ = _grow(_at(45))
    assert plan.days == 45 and plan.size == pytest.approx(growth(45))


def test_the_date_is_decoded_from_the_manifest() -> None:
    cfg = msgspec.toml.decode(b"[trial]\ndate = 2026-07-15\n", type=WorldConfig)
    assert cfg.trial.date == datetime.date(2026, 7, 15)


@pytest.mark.parametrize(
    ("layout", "message"),
    [
        (_layout(planting=datetime.date(2026, 8, 1)), "is before the field's planting_date"),
        (_layout(planting=None), "needs the field's planting_date"),
    ],
)
def test_a_bad_date_is_one_line(layout: FieldLayout, message: str) -> None:
    field = build_field(msgspec.structs.replace(layout, field_book=()))
    cfg = WorldConfig(trial=_at(60))
    with pytest.raises(ValueError, match=message) as exc:
        plan_trial(layout, field, cfg.foliage, cfg.trial, 0)
    assert "\n" not in str(exc.value)


def test_plants_grow_to_the_date() -> None:
    _, _, early = _grow(_at(45))
    _, _, late = _grow(_at(80))
    _, _, mature = _grow(TrialConfig())
    for e, lt, m in zip(early, late, mature, strict=True):
        assert e["height"] < lt["height"] <= m["height"] + 0.05
        assert e["volume_voxel"] < lt["volume_voxel"]
        assert m["height"] <= 1.9 + 0.05  # never above the box
    assert np.mean([r["height"] for r in mature]) == pytest.approx(0.85 * 1.9, abs=0.15)


def test_entries_differ_more_than_their_reps() -> None:
    _, _, rows = _grow(TrialConfig())
    h = np.array([r["height"] for r in rows])
    entry = np.array([r["entry"] for r in rows])
    means = np.array([h[entry == e].mean() for e in np.unique(entry)])
    assert means.var() > 0
    same: list[float] = []
    other: list[float] = []
    for i in range(len(h)):
        for j in range(i + 1, len(h)):
            (same if entry[i] == entry[j] else other).append(abs(h[i] - h[j]))
    assert np.mean(same) < np.mean(other)


def test_an_entrys_effects_depend_on_its_name_only() -> None:
    plan, _, _ = _grow(TrialConfig())
    layout, field, _ = _mini()
    # the same entries elsewhere in the field, and one more entry
    book = layout.field_book
    assert not isinstance(book, str)
    moved = tuple(
        msgspec.structs.replace(r, entry=book[(k + 7) % len(book)].entry)
        for k, r in enumerate(book)
    )
    moved = (*moved[:-1], msgspec.structs.replace(moved[-1], entry="NEW"))
    other = plan_trial(
        msgspec.structs.replace(layout, field_book=moved), field, FoliageConfig(), TrialConfig(), 0
    )
    assert other is not None
    effects = {p.entry: p.effects for p in plan.plots}
    assert all(effects[p.entry] == p.effects for p in other.plots if p.entry != "NEW")
    assert np.array_equal(entry_effects(0, "G01"), entry_effects(0, "G01"))
    assert not np.array_equal(entry_effects(0, "G01"), entry_effects(1, "G01"))


def test_emergence_gaps_leave_holes_in_the_rows() -> None:
    plan, _, rows = _grow(_at(45))
    _, _, full = _grow(_at(45, gap_rate=0.0))
    gaps = np.array([p.gaps for p in plan.plots])
    assert 0 < gaps.mean() < 0.2
    worst = int(gaps.argmax())
    assert rows[worst]["cover"] < full[worst]["cover"]


def test_leaning_plants_reach_into_the_lane_within_the_margin() -> None:
    cfg = TrialConfig(lean_share=0.3)
    plan, fol, rows = _grow(cfg)
    _, field, _ = _mini()
    v = fol.voxel
    leaned = 0
    for p, pp in enumerate(plan.plots):
        box = field.plot_boxes[p]
        pts, _ = fol.occupied_points(p)
        out = np.maximum(box[1] - pts[:, 1], pts[:, 1] - box[4]).max()
        m = cfg.lean_margin if pp.leaning else 0.0
        assert out <= m + v / 2  # voxel centres: within the box + margin
        assert np.all((pts[:, 0] >= box[0]) & (pts[:, 0] <= box[3]))
        if pp.leaning:
            leaned += out > 0.05
        # the true extent counts the leaning parts (voxel faces: half a voxel more)
        r = rows[p]
        assert r["canopy_ymax"] - box[4] <= m + v and box[1] - r["canopy_ymin"] <= m + v
        assert r["canopy_ymax"] - r["canopy_ymin"] >= box[4] - box[1] - 2 * v
    assert leaned > len(plan.plots) // 2


def test_the_same_seed_grows_the_same_trial() -> None:
    _, a = _plants(_at(70))
    _, b = _plants(_at(70), 1)
    _plants.cache_clear()
    _, again = _plants(_at(70))
    assert again is not a
    assert np.array_equal(a.occ, again.occ) and np.array_equal(a.dims, again.dims)
    assert a.occ.shape != b.occ.shape or not np.array_equal(a.occ, b.occ)


def test_a_field_without_a_book_but_a_date_grows_uniform_plants() -> None:
    layout = _layout(book=False)
    field = build_field(layout)
    plan = plan_trial(layout, field, FoliageConfig(), _at(60), 0)
    assert plan is not None and not plan.varied
    assert all(p.gaps == 0 and p.leaning == 0 and p.effects == (1.0, 1.0, 1.0) for p in plan.plots)
    varied = plan_trial(layout, field, FoliageConfig(), TrialConfig(vary=True), 0)
    assert varied is not None and len({p.effects for p in varied.plots}) == len(varied.plots)


def test_the_world_writes_the_plants_truth(tmp_path: Path) -> None:
    layout, field, _ = _mini()
    cfg = WorldConfig(trial=_at(80), targets=TargetConfig(count=0))
    world = World(layout, field, cfg)
    path = write_plant_truth(tmp_path / "sim", world)
    assert path == tmp_path / "sim" / PLANTS_TRUTH
    doc = json.loads(path.read_text())
    assert doc["evaluation_only"] is True
    assert doc["date"] == "2026-07-20" and doc["days_after_planting"] == 80
    assert len(doc["plots"]) == field.n_plots
    row = doc["plots"][0]
    assert row["entry"] == "G03" and row["rep"] == 1 and row["row"] == 1 and row["column"] == 1
    assert 0 < row["height"] < 1.9 and 0 < row["cover"] <= 1
    assert "points" not in row and row["days_after_planting"] == 80
    assert not np.any(world.foliage.occ[world.foliage.occ != EMPTY] > 2)


def test_a_young_crop_hides_less_of_the_gnss_sky() -> None:
    layout, field, _ = _mini()
    # an antenna 1 m above the ground in the lane between the first two rows of plots
    box = field.plot_boxes[0]
    ant = np.array([(box[0] + box[3]) / 2, box[4] + 0.4, 1.0])
    blocked = []
    for trial in (_at(45), TrialConfig()):
        world = World(layout, field, WorldConfig(trial=trial, targets=TargetConfig(count=0)))
        ant[2] = 1.0 + float(world.terrain.height(ant[0], ant[1]))
        blocked.append(world.sky.blocked(ant))
    assert blocked[0] < blocked[1]
