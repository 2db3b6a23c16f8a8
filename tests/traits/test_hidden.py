"""Voxels hidden behind foliage: a solid canopy seen from both lanes is counted whole,
a gap seen through stays empty, and a plot seen from both lanes over part of its
length is counted over that part, carried to its length."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from common.canopy import CanopyDefinition, plot_traits
from common.cropmodel import assign_plots, by_plot
from common.field import load_field
from services.traits.config import TraitsConfig
from services.traits.ground import GroundModel
from services.traits.hidden import _over_seen_slices, occupied_voxels
from services.traits.run import Views
from tests.traits.conftest import TINY

F64 = npt.NDArray[np.float64]
D = CanopyDefinition()  # 10 cm voxels
MIN_SEEN = TraitsConfig().min_seen  # 0.5


def _scan(origin: F64, blocks: list[F64], step_deg: float = 0.25) -> F64:
    """First hits of rays from ``origin`` on solid ``blocks`` [x0, y0, z0, x1, y1, z1]
    and the ground z = 0: what a scanner there would return."""
    az, el = np.meshgrid(
        np.radians(np.arange(0.0, 360.0, step_deg)), np.radians(np.arange(-60.0, 30.0, step_deg))
    )
    az, el = az.ravel(), el.ravel()
    d = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(d[:, 2] < 0, -origin[2] / d[:, 2], np.inf)
        for b in blocks:
            t1, t2 = (b[:3] - origin) / d, (b[3:] - origin) / d
            near = np.nanmax(np.minimum(t1, t2), axis=1)
            far = np.nanmin(np.maximum(t1, t2), axis=1)
            t = np.where((near <= far) & (near > 0) & (near < t), near, t)
    keep = np.isfinite(t) & (t < 20.0)
    return origin + t[keep, None] * d[keep]


def _volume(blocks: list[F64], origins: F64) -> tuple[float, float]:
    """Plot 0's voxel volume from a scan at each of ``origins``: (the voxels holding a
    return, the survey's estimate)."""
    _, field = load_field(TINY)
    scans = [_scan(o, blocks) for o in origins]
    xyz = np.vstack(scans)
    source = np.concatenate([np.full(len(p), k) for k, p in enumerate(scans)]).astype(np.int64)
    ground = GroundModel(
        0.0, 0.0, 0.25, np.zeros((23, 67)), np.ones((23, 67), bool), np.ones((23, 67), np.int64)
    )
    h = xyz[:, 2].copy()
    plot = assign_plots(xyz[:, :2], field.plot_boxes, field.plot_row, field.plot_col, 0.0)
    groups = by_plot(plot, field.n_plots)
    keep = np.ones(len(xyz), bool)
    voxels = occupied_voxels(
        xyz, h, groups, Views(source, origins), keep, field, ground, D, MIN_SEEN
    )
    box = field.plot_boxes[0, [0, 1, 3, 4]]
    inside = (xyz[:, 0] >= box[0]) & (xyz[:, 0] < box[2]) & (xyz[:, 1] >= box[1])
    inside &= xyz[:, 1] < box[3]
    seen = plot_traits(xyz[inside, :2], h[inside], box, D)["volume_voxel"]
    assert voxels[1:].sum() == 0  # nothing in the other plots
    return seen, voxels[0] * D.voxel**3


# the scanner 1 m high in the lanes on either side of plot 0 (x 2.25-5.25, y 1.4-2.4)
LANES = np.array([[3.75, 0.7, 1.0], [3.75, 2.8, 1.0]])


def _truth(blocks: list[F64]) -> float:
    """The definition's voxel volume of plot 0 with every bit of the blocks known (as
    the simulator's truth takes it from its plants): a 2 cm fill of each."""
    _, field = load_field(TINY)
    parts = []
    for b in blocks:
        axes = [np.arange(b[i] + 0.01, b[i + 3], 0.02) for i in range(3)]
        parts.append(np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3))
    p = np.vstack(parts)
    box = field.plot_boxes[0, [0, 1, 3, 4]]
    return plot_traits(p[:, :2], p[:, 2], box, D)["volume_voxel"]


def test_a_solid_canopy_seen_from_both_lanes_is_counted_whole() -> None:
    # a canopy 0.54 m wide and 0.77 m tall in plot 0, its faces off the voxels' edges
    block = [np.array([2.32, 1.63, 0.0, 4.83, 2.17, 0.77])]
    truth = _truth(block)
    seen, whole = _volume(block, LANES)
    assert seen < 0.6 * truth  # the surface alone
    assert abs(whole - truth) < 0.05 * truth


def test_a_gap_seen_through_stays_empty() -> None:
    # two canopies with a 0.8 m gap between them along the row: the hull spans the
    # gap, the rays through it show it empty
    blocks = [
        np.array([2.32, 1.63, 0.0, 3.43, 2.17, 0.77]),
        np.array([4.23, 1.63, 0.0, 5.13, 2.17, 0.77]),
    ]
    truth = _truth(blocks)
    _, whole = _volume(blocks, LANES)
    # the gap filled would add about a third
    assert abs(whole - truth) < 0.05 * truth


def test_a_canopy_seen_from_both_lanes_over_part_of_its_length_is_counted_whole() -> None:
    # a canopy taller than the scanners, and a wall in the far lane that hides a third
    # of its far side from the far scanner: the slices seen from both lanes, carried
    # to the plot's length, give the whole
    block = np.array([2.25, 1.63, 0.0, 5.25, 2.17, 1.33])
    wall = np.array([0.0, 2.45, 0.0, 4.0, 2.5, 3.0])
    origins = np.array([[3.75, 0.7, 1.0], [5.0, 2.8, 1.0]])
    truth = _truth([block])
    _, field = load_field(TINY)
    scans = [_scan(o, [block, wall]) for o in origins]
    xyz = np.vstack(scans)
    box = field.plot_boxes[0, [0, 1, 3, 4]]
    inside = (xyz[:, 0] >= box[0]) & (xyz[:, 0] < box[2]) & (xyz[:, 1] >= box[1])
    inside &= xyz[:, 1] < box[3]
    seen = plot_traits(xyz[inside, :2], xyz[inside, 2], box, D)["seen"]
    assert MIN_SEEN < seen < 0.9  # seen from both lanes over a part only
    _, whole = _volume([block, wall], origins)
    assert abs(whole - truth) < 0.05 * truth


def test_the_seen_slices_mean_is_carried_to_the_plots_length() -> None:
    # a plot 10 voxels long (x), 6 wide: slices 0-4 hold 3 voxels each, 5-9 hold 1;
    # only slices 0-4 hold points on both sides
    occupied = np.zeros((10, 6, 4), bool)
    occupied[:5, 2:5, 0] = True
    occupied[5:, 2, 0] = True
    box = np.array([0.0, 0.0, 1.0, 0.6])
    xs = np.arange(10) * 0.1 + 0.05
    near = np.column_stack([xs, np.full(10, 0.05)])
    far = np.column_stack([xs[:5], np.full(5, 0.55)])
    xy = np.vstack([near, far])
    assert _over_seen_slices(occupied, xy, box, 0.1, MIN_SEEN) == 30.0  # 15 over 5 slices, x 10
    # rows along y: the same plot turned a quarter
    assert (
        _over_seen_slices(
            occupied.transpose(1, 0, 2), xy[:, ::-1], box[[1, 0, 3, 2]], 0.1, MIN_SEEN
        )
        == 30.0
    )
    # no slice seen from both lanes: every slice as counted
    assert _over_seen_slices(occupied, near, box, 0.1, MIN_SEEN) == 20.0


def test_a_plot_seen_from_both_lanes_over_too_few_slices_keeps_every_slice() -> None:
    # one slice of ten seen from both lanes, empty: carried to the plot's length it
    # would say the plot is empty, though its other slices hold returns
    occupied = np.zeros((10, 6, 4), bool)
    occupied[1:, 2, 0] = True
    box = np.array([0.0, 0.0, 1.0, 0.6])
    xy = np.array([[0.05, 0.05], [0.05, 0.55]])
    assert _over_seen_slices(occupied, xy, box, 0.1, 0.0) == 0.0  # no minimum: carried
    assert _over_seen_slices(occupied, xy, box, 0.1, MIN_SEEN) == 9.0
