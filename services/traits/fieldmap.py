"""``fieldmap.png``: the field seen from above in the field frame, every plot filled
by its canopy height, its plot id written on it; plots whose traits are doubtful
(``occluded``, ``no points``) hatched, those with no height in grey."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from common.canopy import column
from services.traits.compute import OK, RunTraits

# beyond this many plots the ids would overlap into a grey smear
MAX_LABELS = 400


def draw(rt: RunTraits, path: Path, trait: str = "height") -> None:
    """Write the field map of ``trait`` to ``path`` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Patch, Rectangle

    boxes = rt.field.plot_boxes
    vals = rt.table.column(trait)
    b = rt.field.bounds
    w, h = b[2] - b[0], b[3] - b[1]
    fig_w = 10.0
    fig, ax = plt.subplots(figsize=(fig_w, max(3.0, min(12.0, fig_w * h / max(w, 1e-9)) + 1.0)))
    try:
        rects = [Rectangle((x0, y0), x1 - x0, y1 - y0) for x0, y0, _, x1, y1, _ in boxes]
        finite = np.isfinite(vals)
        cmap = matplotlib.colormaps["viridis"].with_extremes(bad="lightgrey")
        coll = PatchCollection(rects, cmap=cmap, edgecolor="black", linewidth=0.5)
        coll.set_array(np.ma.masked_invalid(vals))
        if finite.any():
            lo, hi = float(vals[finite].min()), float(vals[finite].max())
            coll.set_clim(lo, hi if hi > lo else lo + 1e-3)
        ax.add_collection(coll)
        fig.colorbar(coll, ax=ax, label=column(trait), shrink=0.8)
        flagged = [r for r, q in zip(boxes, rt.table.quality, strict=True) if q != OK]
        for x0, y0, _, x1, y1, _ in flagged:
            ax.add_patch(
                Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, hatch="///", linewidth=0)
            )
        if len(boxes) <= MAX_LABELS:
            size = max(4.0, min(9.0, 600.0 / len(boxes)))
            for r, box in zip(rt.table.records, boxes, strict=True):
                ax.text(
                    (box[0] + box[3]) / 2, (box[1] + box[4]) / 2, r.plot,
                    ha="center", va="center", fontsize=size, color="white",
                    bbox={"boxstyle": "round,pad=0.15", "fc": "black", "alpha": 0.45, "lw": 0},
                )  # fmt: skip
        if flagged:
            ax.legend(
                handles=[Patch(fill=False, hatch="///", label="occluded / no points")],
                loc="upper right",
                fontsize=8,
            )
        ax.set_xlim(b[0], b[2])
        ax.set_ylim(b[1], b[3])
        ax.set_aspect("equal")
        ax.set_xlabel("field x (m)")
        ax.set_ylabel("field y (m)")
        when = rt.date or "date unknown"
        ax.set_title(f"{rt.layout.name}: {trait} per plot, {when} ({rt.mission})")
        fig.tight_layout()
        fig.savefig(path, dpi=120, format="png")
    finally:
        plt.close(fig)
