"""The survey report's PNG figures (matplotlib, Agg: no display needed).

- ``layout_route.png``: plots, candidate and chosen scan locations, the planned route,
  and where each scan was actually taken (paper Figures 23-25);
- ``stationary.png``: per scan location, the distance from the planned point and the
  pose's spread over the scan (paper Figures 21-22; the log keeps the mean and SD
  of each scan's pose, so the boxes span mean +- 1 SD, whiskers +- 2 SD);
- ``registration_hist.png``: per axis, the point errors of navigation-only and
  navigation + C2C placement against the target-based registration (paper Figure
  28 c-e).

Each function writes one file and returns its name, or None when the data for it is
missing (no plan in the log, no done scan).
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Rectangle

from common.files import atomic_write
from common.geo import wrap_angle
from common.poses import F64, apply
from services.register.metrics import subsample
from services.register.outcome import Registration
from services.register.runlog import RunData

DPI = 150


def layout_route(run: RunData, out: Path) -> str | None:
    if run.plan is None:
        return None
    plan = run.plan
    fig, ax = plt.subplots(figsize=(8, 6))
    for b in plan.plot_boxes.numpy().reshape(-1, 6):
        ax.add_patch(
            Rectangle((b[0], b[1]), b[3] - b[0], b[4] - b[1], fc="#9c9", ec="#474", lw=0.5)
        )
    cand = np.array([(c.x, c.y) for c in plan.candidates]).reshape(-1, 2)
    chosen = {c for c in plan.selected}
    sel = np.array([(c.x, c.y) for c in plan.candidates if c.id in chosen]).reshape(-1, 2)
    ax.plot(cand[:, 0], cand[:, 1], "ks", ms=4, mfc="none", label="candidate locations")
    for lg in plan.legs:
        ax.plot([lg.x0, lg.x1], [lg.y0, lg.y1], "k-", lw=1.0)
    ax.plot(sel[:, 0], sel[:, 1], "rs", ms=8, label="optimal scan locations")
    done = [s for s in run.steps if s.mean_x is not None and s.mean_y is not None]
    if done:
        xy = np.array([(s.mean_x, s.mean_y) for s in done], dtype=np.float64)
        ax.plot(xy[:, 0], xy[:, 1], "b+", ms=10, label="scanned at")
        for s in done:
            ax.annotate(
                str(s.scan_id),
                (s.mean_x or 0.0, s.mean_y or 0.0),
                fontsize=7,
                xytext=(4, 4),
                textcoords="offset points",
            )
    ax.plot(*plan.origin, "g^", ms=9, label="origin")
    ax.set_aspect("equal")
    ax.set_xlabel("field x (m)")
    ax.set_ylabel("field y (m)")
    ax.set_title(
        f"{run.mission['field']}: {len(sel)} locations, {plan.tour.nav} route "
        f"{plan.tour.length:.1f} m"
    )
    ax.legend(loc="upper left", fontsize=7, bbox_to_anchor=(1.0, 1.0))
    return _save(fig, out / "layout_route.png")


def stationary(run: RunData, out: Path) -> str | None:
    steps = [s for s in run.steps if s.mean_x is not None and s.sd_x is not None]
    if not steps:
        return None
    fig, ax = plt.subplots(figsize=(max(6, 0.8 * len(steps) + 2), 4.5))
    ax2 = ax.twinx()
    width = 0.2
    for k, s in enumerate(steps):
        dist = 100 * math.hypot((s.mean_x or 0.0) - s.x, (s.mean_y or 0.0) - s.y)
        herr = 0.0
        if s.mean_yaw is not None and s.yaw is not None:
            herr = math.degrees(wrap_angle(s.mean_yaw - s.yaw))
        boxes = [
            (ax, -1.5, 0.0, 100 * (s.sd_x or 0.0), "tab:blue"),
            (ax, -0.5, 0.0, 100 * (s.sd_y or 0.0), "tab:orange"),
            (ax2, 0.5, herr, math.degrees(s.sd_yaw or 0.0), "tab:red"),
            (ax, 1.5, dist, 0.0, "tab:green"),
        ]
        for a, off, mid, sd, colour in boxes:
            x = k + off * width
            a.add_patch(
                Rectangle(
                    (x - width / 2.5, mid - sd),
                    width / 1.25,
                    max(2 * sd, 0.02),
                    fc=colour,
                    alpha=0.6,
                    ec=colour,
                )
            )
            a.plot([x, x], [mid - 2 * sd, mid + 2 * sd], color=colour, lw=0.8)
    ax.set_xticks(range(len(steps)), [str(s.scan_id) for s in steps])
    ax.set_xlim(-0.6, len(steps) - 0.4)
    ax.set_xlabel("scan")
    ax.set_ylabel("x, y residual / distance to planned (cm)")
    ax2.set_ylabel("heading error (deg)", color="tab:red")
    lim = max(1.0, *(100 * math.hypot((s.mean_x or 0) - s.x, (s.mean_y or 0) - s.y) for s in steps))
    ax.set_ylim(-lim * 0.5, lim * 1.1)
    ax2.set_ylim(-2, 2)
    handles = [
        Rectangle((0, 0), 1, 1, fc=c, alpha=0.6)
        for c in ("tab:blue", "tab:orange", "tab:red", "tab:green")
    ]
    ax.legend(
        handles,
        ["x residual", "y residual", "heading", "distance to planned"],
        fontsize=7,
        loc="upper left",
    )
    ax.set_title("stationary errors per scan location (box: mean +- SD over the scan)")
    return _save(fig, out / "stationary.png")


def registration_hist(reg: Registration, out: Path, samples: int = 5000) -> str | None:
    ref, against = reg.target_poses, "target-based registration"
    rng = np.random.default_rng(0)
    pts = [subsample(s.points, samples, rng) for s in reg.scans]

    def errors(poses: list[F64]) -> F64:
        return np.vstack(
            [apply(p, q) - apply(r, q) for p, r, q in zip(poses, ref, pts, strict=True)]
        )

    methods = [
        ("navigation only", reg.nav_poses, "tab:gray"),
        ("nav + C2C", reg.c2c_poses, "tab:blue"),
    ]
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.8), sharey=True)
    for name, poses, colour in methods:
        e = 100 * errors(poses)
        for a, ax in enumerate(axes):
            lo, hi = np.percentile(e[:, a], [0.5, 99.5])
            ax.hist(
                e[:, a],
                bins=np.linspace(min(lo, -1), max(hi, 1), 80),
                alpha=0.55,
                color=colour,
                label=f"{name}: mean {e[:, a].mean():+.2f}, SD {e[:, a].std():.2f} cm",
            )
    for ax, axis in zip(axes, "XYZ", strict=True):
        ax.set_xlabel(f"d{axis} (cm)")
        ax.legend(fontsize=7)
    axes[0].set_ylabel("points")
    fig.suptitle(f"scan point errors per axis against the {against}")
    return _save(fig, out / "registration_hist.png")


def _save(fig: plt.Figure, path: Path) -> str:
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=DPI))  # report.md links it
    plt.close(fig)
    return path.name
