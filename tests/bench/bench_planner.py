"""Planner benchmark: ``python tests/bench/bench_planner.py [--json out.json]``.

Measures (and prints; targets are reported, never asserted):
- ENGR visibility on the paper's angular grid (77 x 417k rays) after compilation;
- the same rays through Open3D's RaycastingScene (Embree) when open3d is installed;
- ENGR exact (resolution-free) visibility;
- grid-step convergence: locations chosen vs step, and the share of exact pairs found;
- a 40 rows x 50 plots field: visibility, greedy vs exact cover, NN vs optimised tour.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
os.environ.setdefault("NUMBA_CACHE_DIR", str(Path(__file__).resolve().parents[2] / ".cache/numba"))

from common.field import Field, FieldLayout, ScannerModel, build_field, load_field
from services.planner.cover import exact_cover, greedy_cover
from services.planner.route import Navigator
from services.planner.tsp import guided_local_search, nearest_neighbour
from services.planner.visibility import compute_visibility, grid_directions

TARGETS = {
    "engr_grid_s": 1.0,
    "engr_exact_s": 0.5,
    "big_visibility_s": 20.0,
    "exact_cover_gap": 0.01,
    "big_tour_s": 30.0,
}


def timed(fn: Any, *args: Any, **kw: Any) -> tuple[Any, float]:
    t = time.perf_counter()
    out = fn(*args, **kw)
    return out, time.perf_counter() - t


def open3d_grid(field: Field, scanner: ScannerModel) -> dict[str, Any]:
    try:
        import open3d as o3d
    except ImportError:
        print("open3d: not installed, Embree comparison skipped (pip install '.[bench]')")
        return {"skipped": "open3d not installed"}
    scene = o3d.t.geometry.RaycastingScene()
    for b in field.plot_boxes:
        mesh = o3d.geometry.TriangleMesh.create_box(b[3] - b[0], b[4] - b[1], b[5] - b[2])
        mesh.translate(b[:3])
        scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    dirs = grid_directions(scanner).astype(np.float32)
    origins = np.column_stack([field.cand_xy, np.full(field.n_candidates, scanner.height)])
    rays = np.concatenate([np.hstack([np.broadcast_to(o, dirs.shape), dirs]) for o in origins])
    t = time.perf_counter()
    ans = scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))
    cast_s = time.perf_counter() - t
    hits = int(np.isfinite(ans["t_hit"].numpy()).sum())
    print(
        f"open3d:  {len(rays):,} rays in {cast_s:.2f} s ({len(rays) / cast_s / 1e6:.1f} M rays/s)"
        f", {hits:,} hits (ground and cell lookup not included)"
    )
    return {"rays": len(rays), "cast_s": cast_s, "mrays_per_s": len(rays) / cast_s / 1e6}


def engr_section(out: dict[str, Any]) -> None:
    _, field = load_field("engr")
    sc = ScannerModel()
    compute_visibility(field, sc, "grid", step_deg=10.0)  # compile / load the cache
    vis, dt = timed(compute_visibility, field, sc, "grid")
    print(
        f"ENGR grid 0.36 deg: {vis.rays:,} rays in {dt:.2f} s "
        f"({vis.rays / dt / 1e6:.1f} M rays/s; target <= {TARGETS['engr_grid_s']} s)"
    )
    out["engr_grid"] = {"rays": vis.rays, "time_s": dt, "mrays_per_s": vis.rays / dt / 1e6}
    out["open3d"] = open3d_grid(field, sc)
    compute_visibility(field, sc)
    ex, dt = timed(compute_visibility, field, sc)
    print(
        f"ENGR exact: {dt:.3f} s, {ex.rays:,} rays, {len(ex.cell):,} visible pairs "
        f"(target <= {TARGETS['engr_exact_s']} s)"
    )
    out["engr_exact"] = {"time_s": dt, "rays": ex.rays, "pairs": len(ex.cell)}

    exact_m = ex.matrix()
    rows = []
    print("grid-step convergence (ENGR):   step   rays/loc   greedy  exact  pairs found")
    for step in (1.44, 0.72, 0.36, 0.18, 0.09):
        g, dt = timed(compute_visibility, field, sc, "grid", step_deg=step)
        m = g.matrix()
        gr = greedy_cover(m)
        opt = exact_cover(m, time_limit_s=30, hint=gr)
        found = m.multiply(exact_m).nnz / exact_m.nnz
        rows.append(
            {
                "step_deg": step,
                "rays_per_location": g.rays // 77,
                "greedy": len(gr.selected),
                "exact": len(opt.selected),
                "exact_status": opt.status,
                "pairs_found": found,
                "time_s": dt,
            }
        )
        print(
            f"{'':32}{step:5.2f}  {g.rays // 77:9,}  {len(gr.selected):6}  "
            f"{len(opt.selected):5}  {found:6.1%}  ({dt:.1f} s)"
        )
    gr = greedy_cover(exact_m)
    opt = exact_cover(exact_m, time_limit_s=30, hint=gr)
    print(f"{'':32}exact  {'-':>9}  {len(gr.selected):6}  {len(opt.selected):5}  100.0%")
    rows.append({"step_deg": None, "greedy": len(gr.selected), "exact": len(opt.selected)})
    out["convergence"] = rows


def big_section(out: dict[str, Any], tour_limit_s: float) -> None:
    layout = FieldLayout(
        name="big",
        rows=40,
        plots_per_row=50,
        plot_length=3.0,
        plot_width=1.0,
        plot_height=1.9,
        row_spacing=0.8,
        alley_width=1.5,
        headland_width=2.25,
        edge_width=1.4,
    )
    field = build_field(layout)
    vis, dt = timed(compute_visibility, field, ScannerModel())
    print(
        f"40 x 50 field: {field.n_candidates:,} candidates, {field.n_cells:,} cells; exact "
        f"visibility {dt:.1f} s (target <= {TARGETS['big_visibility_s']} s)"
    )
    m = vis.matrix()
    gr = greedy_cover(m)
    opt = exact_cover(m, time_limit_s=60, hint=gr)
    print(
        f"  cover: greedy {len(gr.selected)} ({gr.time_s:.2f} s), exact {len(opt.selected)} "
        f"{opt.status} gap {opt.gap:.2%} ({opt.time_s:.1f} s)"
    )
    res: dict[str, Any] = {
        "candidates": field.n_candidates,
        "cells": field.n_cells,
        "visibility_s": dt,
        "greedy": len(gr.selected),
        "exact": len(opt.selected),
        "exact_status": opt.status,
        "exact_gap": opt.gap,
        "cover_s": opt.time_s,
    }
    pts = np.vstack([field.origin_xy, field.cand_xy[opt.selected]])
    for nav in ("br", "aha"):
        d = Navigator(field, nav).distances(pts)
        nn = nearest_neighbour(d)
        gls = guided_local_search(d, tour_limit_s)
        print(
            f"  tour {nav}: {len(pts)} nodes, nearest neighbour {nn.length:.1f} m, "
            f"GLS {gls.length:.1f} m ({gls.length / nn.length - 1:+.1%}) in {gls.time_s:.1f} s"
        )
        res[f"tour_{nav}"] = {
            "nodes": len(pts),
            "nn_m": nn.length,
            "gls_m": gls.length,
            "gls_s": gls.time_s,
        }
    out["big"] = res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path, help="also write the numbers here")
    ap.add_argument("--tour-limit", type=float, default=20.0, help="GLS seconds (default 20)")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    out: dict[str, Any] = {"cpus": os.cpu_count(), "targets": TARGETS}
    engr_section(out)
    big_section(out, args.tour_limit)
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
        print(f"numbers written to {args.json}")


if __name__ == "__main__":
    main()
