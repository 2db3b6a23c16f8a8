"""Registration targets: the paper's five 200 mm spheres on 1.4-2 m aluminium poles.

The paper ("Experimental fields") deployed five Koppa 200 mm target spheres "throughout
the field" on rods 1.4-2 m high, placed before each survey, i.e. by people who knew
where the robot would scan. Here a pole is a thin vertical cylinder from the ground to
the sphere's underside, and the sphere's centre sits one radius above the pole top.
The ground-truth centres are what a target-based registration is scored on.

Where the sites are given neither in the manifest nor in the field file, they are
chosen for the scan locations a survey can use (the field's candidate lane crossings,
or ``scan_sites``) with the renderer's own 3D ray casting:
with a 1.9 m canopy and the scanner 1 m up, a sphere is seen only along the open lanes
through a scan location (over the canopy it would need a pole several metres tall:
a ray from 1 m must clear 1.9 m at the plot edge 0.4-0.8 m away), and at the paper's
0.36 deg step a 200 mm sphere gets about ``800 / d^2`` points at d metres, so it must
also be near. For every candidate site (free ground off the robot's paths and scan
stops, at least ``clearance`` from any plot) and pole height in the paper's range,
rays from each scanner to the sphere's visible disk give the share of it that the
terrain and plants leave visible, hence the expected number of points. Five sites are
then chosen to maximise the number of scans seeing one, two and three spheres with
at least ``min_points`` points (greedy, then swaps until no single swap helps).

A 1 m scanner in a lane sees only the plus-shaped lanes through it, so one sphere
serves at most two scans that stand in different alleys; with five spheres no
placement can give every scan of a diagonal layout two spheres (see
docs/simulation.md, "The world").
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from common.arrays import F64
from common.field import Field
from services.sim.scene import Scene
from services.sim.terrain import Terrain
from services.sim.world_config import TargetConfig

# placement utility of a scan seeing 0, 1, 2, >= 3 spheres: a second sphere is worth
# most, as it makes the scan solvable by targets with the compensator's tilt (and
# ties it to the other scans that see them); a third makes it solvable without. A
# lone sphere ties nothing (measured on ENGR: 7 scans with two or more against 6
# when the first sphere was worth most)
_WEIGHT = np.array([0.0, 30.0, 200.0, 260.0])


@dataclasses.dataclass(frozen=True, eq=False)
class Targets:
    """Spheres ``(S, 4)`` = [cx, cy, cz, r] and poles ``(S, 5)`` = [x, y, zlo, zhi, r]
    in the ``field`` frame (m)."""

    spheres: F64
    poles: F64

    @property
    def centres(self) -> F64:
        """Ground-truth sphere centres (S, 3), field frame."""
        return self.spheres[:, :3].copy()


@dataclasses.dataclass(frozen=True, eq=False)
class Survey:
    """What the placement plans for: scanner optical centres ``origins`` (S, 3) and
    the robot's paths ``paths`` (P, 2, 2) as segments (field frame, m), and the places
    where it turns or creeps ``stops`` (K, 2)."""

    origins: F64
    paths: F64
    stops: F64


def drive_network(field: Field) -> F64:
    """Segments (P, 2, 2) of the lanes a tour drives between plots: every cross lane
    over the field's width and the two edge lanes over its length."""
    xmin, ymin, xmax, ymax = field.bounds
    segs = [[[x, ymin], [x, ymax]] for x in field.cross_lanes_x]
    segs += [[[xmin, y], [xmax, y]] for y in (field.row_lanes_y[0], field.row_lanes_y[-1])]
    return np.array(segs, dtype=np.float64).reshape(-1, 2, 2)


def build_targets(
    field: Field, terrain: Terrain, cfg: TargetConfig, scene: Scene | None, survey: Survey | None
) -> Targets:
    """Place the targets: ``cfg.sites``, else chosen for ``survey`` seen through
    ``scene`` (terrain and plants, no targets). Raises ValueError for a site inside a
    plot, or when sites must be chosen without a scene and survey."""
    if cfg.pole_max < cfg.pole_min:
        raise ValueError(f"targets.pole_max={cfg.pole_max} < pole_min={cfg.pole_min}")
    if cfg.sites is not None:
        sites = np.array(cfg.sites, dtype=np.float64).reshape(-1, 3)
        inside = _plot_distance(field.plot_boxes, sites[:, :2]) < cfg.radius
        if inside.any():
            x, y, _ = sites[int(np.flatnonzero(inside)[0])]
            raise ValueError(f"targets.sites: ({x}, {y}) is inside or touching a plot")
    elif cfg.count == 0 or (survey is not None and len(survey.origins) == 0):
        sites = np.zeros((0, 3))
    else:
        if scene is None or survey is None:
            raise ValueError("targets: choosing sites needs the scene and the survey")
        sites = choose_sites(field, terrain, scene, survey, cfg)
    ground = terrain.height(sites[:, 0], sites[:, 1])
    top = ground + sites[:, 2]
    spheres = np.column_stack([sites[:, :2], top + cfg.radius, np.full(len(sites), cfg.radius)])
    poles = np.column_stack(
        [sites[:, :2], ground - 0.05, top, np.full(len(sites), cfg.pole_radius)]
    )
    return Targets(np.ascontiguousarray(spheres), np.ascontiguousarray(poles))


def _plot_distance(boxes: F64, xy: F64) -> F64:
    """Horizontal distance from each point (N, 2) to the nearest plot footprint."""
    if len(boxes) == 0:
        return np.full(len(xy), np.inf)
    lo, hi = boxes[None, :, 0:2], boxes[None, :, 3:5]
    gap = np.maximum(np.maximum(lo - xy[:, None, :], xy[:, None, :] - hi), 0.0)
    out: F64 = np.hypot(gap[..., 0], gap[..., 1]).min(axis=1)
    return out


def _segment_distance(xy: F64, segs: F64) -> F64:
    """Distance from each point (N, 2) to the nearest segment (P, 2, 2)."""
    if len(segs) == 0:
        return np.full(len(xy), np.inf)
    a, b = segs[None, :, 0], segs[None, :, 1]
    ab = b - a
    t = np.einsum("npk,npk->np", xy[:, None] - a, np.broadcast_to(ab, (len(xy), *ab.shape[1:])))
    t = np.clip(t / np.maximum((ab**2).sum(-1), 1e-12), 0.0, 1.0)
    d = xy[:, None] - (a + t[..., None] * ab)
    out: F64 = np.hypot(d[..., 0], d[..., 1]).min(axis=1)
    return out


def candidate_sites(field: Field, survey: Survey, cfg: TargetConfig) -> F64:
    """Sphere sites (N, 2) on a ``cfg.grid`` grid over the field and 1 m around it, at
    least ``clearance`` + radius from every plot, ``lane_clearance`` from the robot's
    paths and ``stop_clearance`` from where it stops."""
    xmin, ymin, xmax, ymax = field.bounds
    gx = np.arange(xmin - 1.0, xmax + 1.0 + 1e-9, cfg.grid)
    gy = np.arange(ymin - 1.0, ymax + 1.0 + 1e-9, cfg.grid)
    xy = np.stack(np.meshgrid(gx, gy, indexing="ij"), axis=-1).reshape(-1, 2)
    ok = _plot_distance(field.plot_boxes, xy) >= cfg.clearance + cfg.radius
    ok &= _segment_distance(xy, survey.paths) >= cfg.lane_clearance
    if len(survey.stops):
        near = np.hypot(*(xy[:, None, :] - survey.stops[None, :, :]).transpose(2, 0, 1))
        ok &= near.min(axis=1) >= cfg.stop_clearance
    out: F64 = xy[ok]
    return out


def expected_points(scene: Scene, origins: F64, centres: F64, cfg: TargetConfig) -> F64:
    """(S, M): points a scan from each origin (S, 3) is expected to get on a sphere of
    radius ``cfg.radius`` at each centre (M, 3) at ``cfg.step_deg``: the sphere's solid
    angle over the scan grid's solid angle per point, times the share of seven rays
    to its visible disk that reach it past the terrain and plants of ``scene``."""
    r = cfg.radius
    step = math.radians(cfg.step_deg)
    # the visible disk: its centre and six points at 0.6 r around it
    ang = np.arange(6) * math.pi / 3
    ring = np.column_stack([np.r_[0.0, 0.6 * np.cos(ang)], np.r_[0.0, 0.6 * np.sin(ang)]])
    out = np.zeros((len(origins), len(centres)))
    for s, o in enumerate(origins):
        v = centres - o
        dist = np.linalg.norm(v, axis=1)
        m = np.flatnonzero((dist <= cfg.max_range) & (dist > 0.6 + 2 * r))
        if len(m) == 0:
            continue
        u = v[m] / dist[m, None]
        # two unit vectors across the line of sight (the spheres are never overhead)
        e1 = np.cross(u, [0.0, 0.0, 1.0])
        e1 /= np.linalg.norm(e1, axis=1)[:, None]
        e2 = np.cross(e1, u)
        pts = (
            centres[m, None, :]
            + r * ring[None, :, 0:1] * e1[:, None, :]
            + r * ring[None, :, 1:2] * e2[:, None, :]
        )
        d = pts - o
        dl = np.linalg.norm(d, axis=2)
        dirs = (d / dl[..., None]).reshape(-1, 3)
        t, _, _ = scene.cast(o, dirs, cfg.max_range + 1.0)
        # where each ray enters the sphere
        oc = o - centres[m]
        b = np.einsum("mkj,mj->mk", dirs.reshape(len(m), 7, 3), oc)
        c = (oc**2).sum(axis=1)[:, None] - r * r
        t_in = -b - np.sqrt(np.maximum(b * b - c, 0.0))
        seen = (t.reshape(len(m), 7) > t_in - 1e-3).mean(axis=1)
        solid = 2 * math.pi * (1 - np.sqrt(1 - (r / dist[m]) ** 2))
        cos_el = np.sqrt(1 - u[:, 2] ** 2)
        out[s, m] = seen * solid / (step * step * np.maximum(cos_el, 0.1))
    return out


def select(points: F64, xy: F64, count: int, min_points: float, separation: float) -> list[int]:
    """Indices of ``count`` columns of ``points`` (S scans, M sites at ``xy`` (M, 2))
    maximising the sum over scans of :data:`_WEIGHT` by spheres seen with at least
    ``min_points`` points, sites ``separation`` apart: greedy, then single swaps until
    none helps. Ties go to more points (capped at 100 per scan and sphere)."""
    good = points >= min_points
    bonus = np.minimum(points, 100.0).sum(axis=0) * 1e-3

    def gains(others: list[int]) -> F64:
        base = good[:, others].sum(axis=1) if others else np.zeros(len(points), dtype=np.int64)
        n = np.minimum(base[:, None] + good, 3)
        g: F64 = _WEIGHT[n].sum(axis=0) + bonus
        for o in others:
            g[np.hypot(*(xy - xy[o]).T) < separation] = -np.inf
        return g

    chosen: list[int] = []
    for _ in range(min(count, points.shape[1])):
        g = gains(chosen)
        best = int(np.argmax(g))
        if not np.isfinite(g[best]):
            break
        chosen.append(best)
    for _ in range(10):
        improved = False
        for k in range(len(chosen)):
            others = chosen[:k] + chosen[k + 1 :]
            g = gains(others)
            best = int(np.argmax(g))
            if g[best] > g[chosen[k]] + 1e-9:
                chosen[k], improved = best, True
        if not improved:
            break
    return chosen


def choose_sites(
    field: Field, terrain: Terrain, scene: Scene, survey: Survey, cfg: TargetConfig
) -> F64:
    """``cfg.count`` sites (K, 3) = [x, y, pole height] for ``survey`` (see the module
    docstring). Raises ValueError when no candidate site is free."""
    xy = candidate_sites(field, survey, cfg)
    if len(xy) == 0:
        raise ValueError(f"field {field.name!r}: no free place for sphere targets")
    heights = np.linspace(cfg.pole_min, cfg.pole_max, 4 if cfg.pole_max > cfg.pole_min else 1)
    ground = terrain.height(xy[:, 0], xy[:, 1])
    cand = np.vstack([np.column_stack([xy, np.full(len(xy), h)]) for h in heights])
    centres = np.column_stack(
        [cand[:, :2], np.tile(ground, len(heights)) + cand[:, 2] + cfg.radius]
    )
    pts = expected_points(scene, survey.origins, centres, cfg)
    chosen = select(pts, cand[:, :2], cfg.count, cfg.min_points, cfg.min_separation)
    out: F64 = cand[chosen]
    return out
