"""Plants: an irregular canopy inside every plot box, stored as fine occupancy grids.

Each plot gets its own voxel grid (``voxel`` metres, 4 cm by default) aligned with its
box in the ``field`` frame and tall enough to hold the box above the lowest ground
under it. Plants stand along the plot's centre line, rooted on the terrain: a leaning
main stem, branches rising outwards, and porous leaf clusters, all kept inside a
canopy envelope (an ellipsoid-like profile, widest a little below mid-height) that
never leaves the plot box (a trial's plants, :class:`PlotGrowth` from
:mod:`services.sim.trial`, may lean a margin past it). Voxel values are :data:`EMPTY`,
:data:`LEAF` or :data:`STEM`. A 3 x 1 x 1.9 m plot is ~94 k voxels (one byte each,
~14 % filled), so ENGR's 60 plots take ~5.7 MB. A horizontal ray is stopped after
~0.3-0.5 m of canopy.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from common.arrays import F64, I64, U8
from services.sim.plant_config import FoliageConfig
from services.sim.terrain import Terrain

Mask = npt.NDArray[np.bool_]
Rng = np.random.Generator

EMPTY, LEAF, STEM = 0, 1, 2


@dataclasses.dataclass(frozen=True, eq=False)
class Foliage:
    """Per-plot voxel grids: plot ``p`` has ``dims[p]`` = (nx, ny, nz) voxels of size
    ``voxel`` from corner ``origin[p]`` (field frame, m), stored x-major in
    ``occ[offset[p] : offset[p + 1]]`` (index ``(ix * ny + iy) * nz + iz``)."""

    voxel: float
    origin: F64  # (P, 3)
    dims: I64  # (P, 3)
    offset: I64  # (P + 1,)
    occ: U8  # (V,)

    @property
    def n_plots(self) -> int:
        return int(self.origin.shape[0])

    def grid(self, p: int) -> U8:
        """Plot ``p``'s voxels as an (nx, ny, nz) view."""
        nx, ny, nz = (int(v) for v in self.dims[p])
        return self.occ[self.offset[p] : self.offset[p + 1]].reshape(nx, ny, nz)

    def grid_boxes(self) -> F64:
        """(P, 6) boxes ``[xmin, ymin, zmin, xmax, ymax, zmax]`` of the voxel grids."""
        return np.hstack([self.origin, self.origin + self.dims * self.voxel])

    def occupied_points(self, p: int) -> tuple[F64, U8]:
        """Centres (K, 3) and values (K,) of plot ``p``'s occupied voxels."""
        g = self.grid(p)
        idx = np.argwhere(g != EMPTY)
        return self.origin[p] + (idx + 0.5) * self.voxel, g[tuple(idx.T)]


@dataclasses.dataclass(frozen=True, eq=False)
class PlotGrowth:
    """One plot's plants instead of :class:`FoliageConfig`'s uniform draw: per planted
    position along the row its plant's height (m, clipped to the box), whether it
    ``emerged``, its lean across the row (degrees from vertical; + towards larger y for
    a row along x, larger x otherwise; 0 upright); ``width``: the canopy half-width as
    a factor of the plot's; ``margin``: how far (m) leaning plants may reach past the
    box's long sides (the grid grows by it)."""

    heights: F64
    emerged: Mask
    lean_deg: F64
    width: float
    margin: float


def build_foliage(
    plot_boxes: F64,
    terrain: Terrain,
    cfg: FoliageConfig,
    seed: int,
    plans: Sequence[PlotGrowth] | None = None,
) -> Foliage:
    """Grow plants in every plot of ``plot_boxes`` (P, 6), seeded per plot so a plot's
    plants do not change when other plots are added; ``plans``: one :class:`PlotGrowth`
    per plot (None: the uniform plants of ``cfg``). Raises ValueError on bad boxes."""
    boxes = np.asarray(plot_boxes, dtype=np.float64)
    if boxes.ndim != 2 or boxes.shape[1] != 6 or np.any(boxes[:, 3:] <= boxes[:, :3]):
        raise ValueError(f"plot_boxes: expected (P, 6) boxes with max > min, got {boxes.shape}")
    if cfg.height_max < cfg.height_min:
        raise ValueError(f"foliage.height_max={cfg.height_max} < height_min={cfg.height_min}")
    if plans is not None and len(plans) != len(boxes):
        raise ValueError(f"plans: {len(plans)} plot plans for {len(boxes)} plots")
    v = cfg.voxel
    origins, dims, grids = [], [], []
    for p, box in enumerate(boxes):
        rng = np.random.default_rng(np.random.SeedSequence([seed, 0xF011, p]))
        growth = None if plans is None else plans[p]
        # a trial's leaning plants may reach past the long sides (facing the lanes)
        gbox, side = box.copy(), 1 if box[3] - box[0] >= box[4] - box[1] else 0
        gbox[[side, side + 3]] += (0.0, 0.0) if growth is None else (-growth.margin, growth.margin)
        xs = np.linspace(gbox[0], gbox[3], 7)
        ys = np.linspace(gbox[1], gbox[4], 4)
        ground = terrain.height(xs[:, None], ys[None, :])
        z0 = float(ground.min()) + box[2] - v
        top = float(ground.max()) + box[5]
        org = np.array([gbox[0], gbox[1], z0])
        n = np.ceil((np.array([gbox[3], gbox[4], top]) - org) / v).astype(np.int64)
        grid = np.zeros(tuple(int(k) for k in n), dtype=np.uint8)
        pts, vals = _grow_plot(box, terrain, cfg, rng, growth)
        idx = np.floor((pts - org) / v).astype(np.int64)
        # the envelope is clipped to the box (+ margin), so dropping out-of-grid points
        # only trims the odd voxel that rounding pushed past the box face
        ok = np.all((idx >= 0) & (idx < n), axis=1)
        idx, vals = idx[ok], vals[ok]
        order = np.argsort(vals, kind="stable")  # stems written last win over leaves
        grid[idx[order, 0], idx[order, 1], idx[order, 2]] = vals[order]
        origins.append(org)
        dims.append(n)
        grids.append(grid.ravel())
    sizes = np.array([g.size for g in grids], dtype=np.int64)
    return Foliage(
        voxel=v,
        origin=np.array(origins, dtype=np.float64),
        dims=np.array(dims, dtype=np.int64),
        offset=np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
        occ=np.concatenate(grids).astype(np.uint8),
    )


def _envelope(zrel: F64) -> F64:
    """Canopy half-width as a fraction of the plot's, at relative height ``zrel`` in
    [0, 1]: narrow at the base, widest at 40 % of the height, round top."""
    z = np.clip(zrel, 0.0, 1.0)
    return np.where(
        z < 0.4, 0.35 + 0.65 * np.sin(z / 0.4 * math.pi / 2), np.sqrt(1 - ((z - 0.4) / 0.6) ** 2)
    )


def _segment_points(a: F64, b: F64, step: float, radius: float, rng: Rng) -> tuple[F64, I64]:
    """Points along the segments a[k] -> b[k] every ``step``, jittered by ``radius``,
    and the segment ``k`` of each."""
    length = np.linalg.norm(b - a, axis=1)
    n = np.maximum(np.ceil(length / step).astype(np.int64), 1) + 1
    k = np.repeat(np.arange(len(a)), n)
    f = np.concatenate([np.linspace(0, 1, m) for m in n])
    pts = a[k] + (b - a)[k] * f[:, None]
    return pts + rng.uniform(-radius, radius, pts.shape), k


def _plants(
    box: F64, terrain: Terrain, cfg: FoliageConfig, rng: Rng, growth: PlotGrowth | None
) -> tuple[F64, F64, F64, float, float]:
    """Roots and stem tips (n, 3) of the plot's standing plants, their lean (n,) in
    radians, and the canopy envelope's height and half-width (m)."""
    lx, ly, hz = box[3] - box[0], box[4] - box[1], box[5] - box[2]
    cx, cy = (box[0] + box[3]) / 2, (box[1] + box[4]) / 2
    # plants grow along the longer side (the planted row)
    along_x = lx >= ly
    length, half_w = (lx, ly / 2) if along_x else (ly, lx / 2)
    n_plants = max(1, round(length * cfg.plants_per_m)) if growth is None else len(growth.heights)
    s = (np.arange(n_plants) + rng.uniform(0.2, 0.8, n_plants)) / n_plants * length - length / 2
    lateral = rng.normal(0.0, 0.03, n_plants)
    px = cx + (s if along_x else lateral)
    py = cy + (lateral if along_x else s)
    base = terrain.height(px, py)
    if growth is None:
        heights = hz * rng.uniform(cfg.height_min, cfg.height_max, n_plants)
    else:
        heights = np.minimum(growth.heights, hz)
    lean = rng.normal(0.0, 0.05, (n_plants, 2))
    root = np.stack([px, py, base + box[2]], axis=1)
    tip = root + np.column_stack([lean, heights])
    if growth is None:
        return root, tip, np.zeros(n_plants), hz, half_w
    up = growth.emerged  # failed positions grow nothing
    env_h = float(heights[up].max()) if up.any() else hz
    return root[up], tip[up], np.radians(growth.lean_deg[up]), env_h, half_w * growth.width


def _grow_plot(
    box: F64, terrain: Terrain, cfg: FoliageConfig, rng: Rng, growth: PlotGrowth | None = None
) -> tuple[F64, U8]:
    """Stem and leaf points (field frame) of one plot, all inside ``box`` in xy (its
    leaning plants' inside the box + ``growth.margin``)."""
    root, tip, tilt, env_h, env_w = _plants(box, terrain, cfg, rng, growth)
    if len(root) == 0:
        return np.zeros((0, 3)), np.zeros(0, np.uint8)
    cx, cy = (box[0] + box[3]) / 2, (box[1] + box[4]) / 2
    along_x = box[3] - box[0] >= box[4] - box[1]
    step = cfg.voxel / 2
    stem0, own0 = _segment_points(root, tip, step, cfg.stem_radius, rng)
    stems, leaves, owners, leaf_owners = [stem0], [], [own0], []
    nb = cfg.branches_per_plant
    for k in range(len(root)):
        if nb == 0:
            break
        f = np.sort(rng.uniform(0.15, 0.95, nb))
        start = root[k] + (tip[k] - root[k]) * f[:, None]
        ang = rng.uniform(0, 2 * math.pi, nb)
        reach = _envelope(f) * env_w * rng.uniform(0.6, 1.3, nb)
        # branches reach farther along the row than across it (cotton sympodia)
        stretch = np.where(np.abs(np.cos(ang)) > 0.5, 1.4, 1.0) if along_x else 1.0
        end = start + np.column_stack(
            [np.cos(ang) * reach * stretch, np.sin(ang) * reach, reach * rng.uniform(0.2, 0.6, nb)]
        )
        branch, _ = _segment_points(start, end, step, cfg.stem_radius * 0.6, rng)
        stems.append(branch)
        owners.append(np.full(len(branch), k))
        nl = cfg.leaves_per_branch
        if nl == 0:
            continue
        g = rng.uniform(0.3, 1.0, (nb, nl))
        centres = (start[:, None, :] + (end - start)[:, None, :] * g[..., None]).reshape(-1, 3)
        leaves.append(_leaf_clusters(centres, cfg, rng))
        leaf_owners.append(np.full(len(leaves[-1]), k))
    pts = np.concatenate(stems + leaves)
    owner = np.concatenate(owners + leaf_owners)
    vals = np.concatenate(
        [np.full(sum(len(a) for a in stems), STEM, np.uint8)]
        + [np.full(len(a), LEAF, np.uint8) for a in leaves]
    )
    # keep everything inside the envelope (upright) and the box (the plot's truth)
    zrel = (pts[:, 2] - terrain.height(pts[:, 0], pts[:, 1]) - box[2]) / env_h
    off = np.abs(pts[:, 1] - cy) if along_x else np.abs(pts[:, 0] - cx)
    keep = (off <= _envelope(zrel) * env_w + cfg.leaf_radius) & (zrel <= 1.0)
    pts, vals, owner = pts[keep], vals[keep], owner[keep]
    leaning = tilt[owner] != 0
    if leaning.any():
        pts = _lean(pts, owner, root, tilt, along_x)
    margin = 0.0 if growth is None else growth.margin
    return _clip(pts, vals, leaning, box, margin, along_x, terrain)


def _lean(pts: F64, owner: I64, root: F64, tilt: F64, along_x: bool) -> F64:
    """``pts`` of plant ``owner`` turned by ``tilt[owner]`` (rad) about the horizontal
    axis along the row through its root: a rigid lean, so the plant gets lower too."""
    u, r, t = (1 if along_x else 0), root[owner], tilt[owner]
    du, dz = pts[:, u] - r[:, u], pts[:, 2] - r[:, 2]
    out = pts.copy()
    out[:, u] = r[:, u] + du * np.cos(t) + dz * np.sin(t)
    out[:, 2] = r[:, 2] - du * np.sin(t) + dz * np.cos(t)
    return out


def _clip(
    pts: F64, vals: U8, leaning: Mask, box: F64, margin: float, along_x: bool, terrain: Terrain
) -> tuple[F64, U8]:
    """The points inside ``box`` in xy; those of ``leaning`` plants inside it widened
    by ``margin`` across the row, and above the ground."""
    u, a = (1, 0) if along_x else (0, 1)
    m = np.where(leaning, margin, 0.0)
    keep = (pts[:, a] >= box[a]) & (pts[:, a] < box[a + 3])
    keep &= (pts[:, u] >= box[u] - m) & (pts[:, u] < box[u + 3] + m)
    if leaning.any():
        keep &= (pts[:, 2] - terrain.height(pts[:, 0], pts[:, 1]) >= box[2]) | ~leaning
    return pts[keep], vals[keep]


def _leaf_clusters(centres: F64, cfg: FoliageConfig, rng: np.random.Generator) -> F64:
    """Random points filling ~``leaf_fill`` of the voxels of a ball around each centre."""
    r = cfg.leaf_radius
    vol_vox = (4 / 3) * math.pi * r**3 / cfg.voxel**3
    n_per = max(1, round(vol_vox * cfg.leaf_fill))
    d = rng.standard_normal((len(centres), n_per, 3))
    d /= np.linalg.norm(d, axis=2, keepdims=True)
    rad = r * rng.uniform(0, 1, (len(centres), n_per, 1)) ** (1 / 3)
    # flatten clusters vertically: leaves are blades, not balls
    pts = centres[:, None, :] + d * rad * np.array([1.0, 1.0, 0.5])
    return pts.reshape(-1, 3)
