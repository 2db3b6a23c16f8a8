"""Plan files: plan.json, plan.geojson, waypoints.csv and plan.png (and each robot's
waypoints-robot<N>.csv when several share the survey), each written whole or not at
all.

plan.geojson is in WGS84 (lon, lat) when the layout is georeferenced; otherwise it holds
``field`` frame metres and says so in a top-level ``"frame": "field"`` member (plain
GeoJSON readers will then misplace it, by design visible rather than silently wrong).
"""

from __future__ import annotations

import csv
import logging
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import msgspec
import numpy as np
from matplotlib.collections import LineCollection, PolyCollection

from common.arrays import F64
from common.field_geojson import field_to_wgs84
from common.files import atomic_write, write_atomic
from common.messages.nav import Leg
from common.messages.plan import PlanResult
from services.planner.waypoints import heading

log = logging.getLogger(__name__)


def write_json(result: PlanResult, path: Path) -> Path:
    """The whole result, decodable with ``msgspec.json.decode(data, type=PlanResult)``."""
    data = msgspec.json.format(msgspec.json.encode(result), indent=1)
    write_atomic(path, data)
    return path


def write_waypoints_csv(legs: list[Leg], path: Path) -> Path:
    """One row per leg: field-frame metres, headings in radians (REP-103)."""
    atomic_write(path, lambda tmp: _waypoints(legs, tmp))
    return path


def _waypoints(legs: list[Leg], path: Path) -> None:
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["leg", "x0", "y0", "x1", "y1", "heading", "final_yaw", "scan_id"])
        for k, leg in enumerate(legs):
            fy = "" if leg.final_yaw is None else f"{leg.final_yaw:.6f}"
            sid = "" if leg.scan_id is None else leg.scan_id
            w.writerow(
                [
                    k,
                    f"{leg.x0:.3f}",
                    f"{leg.y0:.3f}",
                    f"{leg.x1:.3f}",
                    f"{leg.y1:.3f}",
                    f"{heading(leg):.6f}",
                    fy,
                    sid,
                ]
            )


def write_geojson(result: PlanResult, path: Path) -> Path:
    """Plots (polygons), candidates (points, ``selected`` and tour ``visit`` index) and
    the route (one LineString)."""
    lay = result.layout
    geo = lay.georeferenced

    def conv(xy: F64) -> list[list[float]]:
        pts = field_to_wgs84(lay, xy) if geo else np.asarray(xy, dtype=np.float64)
        return [[round(float(a), 9), round(float(b), 9)] for a, b in pts]

    feats: list[dict[str, Any]] = []
    for p, b in enumerate(result.plot_boxes.numpy()):
        ring = np.array([[b[0], b[1]], [b[3], b[1]], [b[3], b[4]], [b[0], b[4]], [b[0], b[1]]])
        feats.append(
            {
                "type": "Feature",
                "geometry": {"type": "Polygon", "coordinates": [conv(ring)]},
                "properties": {"kind": "plot", "plot": p, "height": float(b[5])},
            }
        )
    visit = {cid: k for k, cid in enumerate(result.tour.order[:-1])}
    chosen = set(result.selected)
    for c in result.candidates:
        feats.append(
            {
                "type": "Feature",
                "geometry": {"type": "Point", "coordinates": conv(np.array([[c.x, c.y]]))[0]},
                "properties": {
                    "kind": "candidate",
                    "id": c.id,
                    "selected": c.id in chosen,
                    "visit": visit.get(c.id),
                    "cells_seen": c.cells_seen,
                },
            }
        )
    if result.legs:
        line = np.array(
            [[g.x0, g.y0] for g in result.legs] + [[result.legs[-1].x1, result.legs[-1].y1]]
        )
        feats.append(
            {
                "type": "Feature",
                "geometry": {"type": "LineString", "coordinates": conv(line)},
                "properties": {
                    "kind": "route",
                    "nav": result.tour.nav,
                    "length_m": result.tour.length,
                },
            }
        )
    doc: dict[str, Any] = {"type": "FeatureCollection", "features": feats}
    if not geo:
        doc["frame"] = "field"
    data = msgspec.json.encode(doc)
    write_atomic(path, data)
    return path


def write_png(result: PlanResult, path: Path) -> Path:
    """Two panels like the paper's Figures 16 and 18: the candidates with the chosen
    ones, and the tour along the lanes."""
    boxes = result.plot_boxes.numpy()
    xs = np.array([c.x for c in result.candidates])
    ys = np.array([c.y for c in result.candidates])
    chosen = set(result.selected)
    sel = np.array([c.id in chosen for c in result.candidates], dtype=bool)
    lo = np.minimum(boxes[:, :2].min(axis=0), [xs.min(), ys.min()]) - 1.0
    hi = np.maximum(boxes[:, 3:5].max(axis=0), [xs.max(), ys.max()]) + 1.0
    aspect = (hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-6)
    fig, axes = plt.subplots(1, 2, figsize=(14, max(3.5, min(14.0, 7 * aspect))))
    few = len(result.candidates) <= 200
    # the plots as one collection each: one artist, not one per plot (10,000 on a
    # breeding programme's field)
    corners = boxes[:, [[0, 1], [3, 1], [3, 4], [0, 4]]]  # (P, 4, 2) polygons
    for ax in axes:
        ax.add_collection(PolyCollection(list(corners), fc="#7fbf7f", ec="#2e7d32", lw=0.5))
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal")
        ax.set_xlabel("x along rows (m)")
        ax.set_ylabel("y (m)")
    a0, a1 = axes
    a0.scatter(xs[~sel], ys[~sel], marker="s", s=14 if few else 3, c="black", label="candidate")
    a0.scatter(xs[sel], ys[sel], marker="s", s=30 if few else 6, c="red", label="selected")
    if few:
        for c in result.candidates:
            a0.annotate(
                str(c.id),
                (c.x, c.y),
                xytext=(2, 2),
                textcoords="offset points",
                fontsize=6,
                color="red" if c.id in chosen else "black",
            )
    cov = result.cover
    a0.set_title(
        f"{result.field}: {cov.count} of {len(result.candidates)} locations "
        f"({cov.method}, {cov.status}); {cov.cells_covered}/{cov.cells_coverable} cells"
    )
    a0.legend(loc="upper right", fontsize=7)
    _draw_routes(a1, result, 1.2 if few else 0.6)
    a1.scatter(xs[sel], ys[sel], marker="*", s=80 if few else 10, c="red", zorder=3)
    a1.scatter(
        [result.origin[0]], [result.origin[1]], marker="o", s=60, c="blue", zorder=3, label="Origin"
    )
    if few:
        for k, cid in enumerate(result.tour.order[1:-1], start=1):
            c = next(c for c in result.candidates if c.id == cid)
            a1.annotate(
                f"{k}",
                (c.x, c.y),
                xytext=(3, -8),
                textcoords="offset points",
                fontsize=7,
                color="blue",
            )
    t, f = result.tour, result.fleet
    a1.set_title(
        f"{t.nav.upper()} tour {t.length:.1f} m ({t.method}, {t.status}); "
        f"nearest neighbour {t.nn_length:.1f} m"
        if f is None
        else f"{len(f.parts)} robots: the slowest {f.makespan_s / 3600:.1f} h, "
        f"one robot {f.one_robot_s / 3600:.1f} h"
    )
    a1.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=130))
    plt.close(fig)
    return path


def _draw_routes(ax: Any, result: PlanResult, lw: float) -> None:
    """The tour's legs in black, or each robot's share in a colour of its own."""
    shares: list[tuple[Any, list[Leg], str]]
    if result.fleet is None:
        shares = [("black", result.legs, "")]
    else:
        cmap = plt.get_cmap("tab10")
        parts = result.fleet.parts
        shares = [(cmap(k % 10), p.legs, f"robot {p.robot}") for k, p in enumerate(parts)]
    for colour, legs, label in shares:
        segs = [[(g.x0, g.y0), (g.x1, g.y1)] for g in legs]
        ax.add_collection(LineCollection(segs, colors=[colour], lw=lw, label=label or None))


def write_all(result: PlanResult, out_dir: str | Path) -> dict[str, Path]:
    """Write the plan files into ``out_dir`` (created): plan.json, plan.geojson,
    waypoints.csv (the tour), plan.png, and with several robots each one's
    waypoints-robot<N>.csv; returns name -> path."""
    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    files = {
        "plan.json": write_json(result, d / "plan.json"),
        "plan.geojson": write_geojson(result, d / "plan.geojson"),
        "waypoints.csv": write_waypoints_csv(result.legs, d / "waypoints.csv"),
        "plan.png": write_png(result, d / "plan.png"),
    }
    for part in result.fleet.parts if result.fleet is not None else []:
        name = f"waypoints-robot{part.robot}.csv"
        files[name] = write_waypoints_csv(part.legs, d / name)
    log.info("plan files written to %s", d)
    return files
