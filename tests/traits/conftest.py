"""Synthetic registered surveys for the traits tests: a field, a ground plane (flat or
sloped), box-shaped canopies of known height and cover per plot, the merged cloud
written to ``registered.laz`` with laspy and a mission log holding the plan, written
through the mission service's own MissionLog."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import laspy
import msgspec
import numpy as np
import numpy.typing as npt
import pytest

from common.field import Field, FieldLayout, build_field, load_field
from common.messages.core import Array
from common.messages.plan import PlanResult
from services.mission.log import MissionLog

TINY = Path(__file__).resolve().parents[1] / "data" / "tiny.toml"
F64 = npt.NDArray[np.float64]
# 2024-06-03T00:00:00Z
CREATED_NS = 1_717_372_800 * 10**9


@dataclasses.dataclass(frozen=True)
class Canopy:
    """A box of canopy ``height`` m above the ground over the middle ``cover`` share
    of a plot's width (its whole length); ``None`` height: the plot holds no point
    at all (ground included); ``seen``: the share of the plot's length scanned."""

    height: float | None
    cover: float = 1.0
    seen: float = 1.0


def ground_z(xy: F64, slope: tuple[float, float]) -> F64:
    return 100.0 + slope[0] * xy[:, 0] + slope[1] * xy[:, 1]


def _jittered(lo: F64, hi: F64, spacing: float, rng: np.random.Generator) -> F64:
    """Points on a jittered grid over the rectangle [lo, hi] (2,)."""
    xs = np.arange(lo[0] + spacing / 2, hi[0], spacing)
    ys = np.arange(lo[1] + spacing / 2, hi[1], spacing)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    return xy + rng.uniform(-spacing / 3, spacing / 3, xy.shape)


def synthetic_cloud(
    field: Field,
    canopies: list[Canopy],
    slope: tuple[float, float] = (0.0, 0.0),
    spacing: float = 0.02,
    seed: int = 0,
) -> F64:
    """The (N, 3) cloud: ground everywhere it is not hidden under a canopy (or cut
    away from an unseen plot), canopy tops with 2 mm noise, and walls down the
    canopy's long sides."""
    rng = np.random.default_rng(seed)
    b = field.bounds
    xy = _jittered(b[:2], b[2:], spacing, rng)
    keep = np.ones(len(xy), dtype=bool)
    parts = []
    for box, c in zip(field.plot_boxes, canopies, strict=True):
        x0, y0, _, x1, y1, _ = box
        inside = (xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)
        if c.height is None:  # 1 cm around: the LAZ's mm rounding puts none on the edge
            keep &= ~(
                (xy[:, 0] >= x0 - 0.01)
                & (xy[:, 0] <= x1 + 0.01)
                & (xy[:, 1] >= y0 - 0.01)
                & (xy[:, 1] <= y1 + 0.01)
            )
            continue
        half = (y1 - y0) * c.cover / 2
        cy0, cy1 = (y0 + y1) / 2 - half, (y0 + y1) / 2 + half
        cx1 = x0 + (x1 - x0) * c.seen
        keep &= ~(inside & (xy[:, 1] >= cy0) & (xy[:, 1] <= cy1))
        keep &= ~(inside & (xy[:, 0] > cx1))  # the unseen part: no ground either
        top = _jittered(np.array([x0, cy0]), np.array([cx1, cy1]), spacing, rng)
        z = ground_z(top, slope) + c.height + rng.normal(0, 0.002, len(top))
        parts.append(np.column_stack([top, z]))
        for wy in (cy0, cy1):  # the long sides, seen from the lanes
            w = _jittered(np.array([x0, 0.0]), np.array([cx1, c.height]), spacing, rng)
            wxy = np.column_stack([w[:, 0], np.full(len(w), wy)])
            parts.append(np.column_stack([wxy, ground_z(wxy, slope) + w[:, 1]]))
    g = xy[keep]
    parts.append(np.column_stack([g, ground_z(g, slope) + rng.normal(0, 0.003, len(g))]))
    return np.concatenate(parts)


def write_laz(path: Path, xyz: F64) -> None:
    header = laspy.LasHeader(point_format=1, version="1.4")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.floor(xyz.min(axis=0))
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.write(str(path))


@pytest.fixture(scope="session")
def tiny_plan() -> PlanResult:
    """A plan of the tiny field, made once (the planner is the slow part)."""
    from services.planner.core import plan

    layout, field = load_field(TINY)
    return plan(layout, field=field)


def plan_for(base: PlanResult, layout: FieldLayout) -> PlanResult:
    """``base`` made over for another layout: only the layout and plot boxes matter
    here (the route is not read by the traits)."""
    boxes = build_field(layout).plot_boxes
    return msgspec.structs.replace(
        base, field=layout.name, layout=layout, plot_boxes=Array.of(boxes)
    )


def write_run(run: Path, plan: PlanResult, xyz: F64 | None, created_ns: int = CREATED_NS) -> Path:
    """A run folder: ``mission.db`` holding ``plan`` and, unless None,
    ``registered.laz`` holding ``xyz``."""
    log = MissionLog(run / "mission.db")
    log.create(run.name, plan.field, created_ns, msgspec.json.encode(plan).decode(), [])
    log.set_state("done")
    log.close()
    if xyz is not None:
        write_laz(run / "registered.laz", xyz)
    return run


# the tiny field's six plots (plot order: bottom row left to right, then the top row)
CANOPIES = [
    Canopy(0.6),
    Canopy(0.8, cover=0.5),
    Canopy(None),  # nothing seen
    Canopy(0.3, cover=0.75),
    Canopy(1.2, seen=0.4),  # occluded
    Canopy(0.15),
]
SLOPE = (0.05, 0.02)


def book_layout(layout: FieldLayout) -> FieldLayout:
    """``layout`` with a field book: plot ids 101.., entries and two reps."""
    from common.field_model import PlotRecord

    book = tuple(
        PlotRecord(
            plot=str(101 + r * layout.plots_per_row + c),
            row=r + 1,
            column=c + 1,
            entry=f"G{(r * layout.plots_per_row + c) % 3 + 1}",
            rep=r + 1,
        )
        for r in range(layout.rows)
        for c in range(layout.plots_per_row)
    )
    return msgspec.structs.replace(layout, field_book=book)


@pytest.fixture(scope="session")
def sloped_run(tiny_plan: PlanResult, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A registered survey of the tiny field (with a field book) on sloped ground."""
    layout = book_layout(load_field(TINY)[0])
    pr = plan_for(tiny_plan, layout)
    xyz = synthetic_cloud(build_field(layout), CANOPIES, slope=SLOPE)
    return write_run(tmp_path_factory.mktemp("runs") / "tiny-1", pr, xyz)
