"""The paper's registration figures (arXiv:2404.04404, ENGR field), for comparison
with ours. Lengths in centimetres.

Table 1 ("Registration errors comparison"): target statistics (mean, horizontal and
vertical error of the spheres) and scan point statistics (max and mean point error)
of the target-based registration and of navigation sensors + C2C, both from FARO
SCENE. Its target statistics are SCENE's sphere residuals, ours are the sphere
centres placed by a method's poses against the target-based positions, so they do
not compare like for like. Its scan point statistics are not errors against a
reference either: the target-based row has them too (1.37 cm mean), which it could
not against itself. They are SCENE's overlap residuals, the distances between the
points of overlapping scans once registered, and ours are computed the same way
(:func:`services.register.metrics.overlap_stats`, within the paper's 30 cm search
radius). Neither is an error against the truth. The Hausdorff-style distance of the
nav + C2C cloud to the target-based cloud: 1.25 cm mean, SD 0.82 cm, 85 % of points
below 2 cm, 95 % below 3 cm.
"""

from __future__ import annotations

from typing import Any

Json = dict[str, Any]
# method (as in report.json) -> Table 1's row
TABLE1: dict[str, Json] = {
    "target_based": {
        "label": "Target-based",
        "target_mean_cm": 0.59,
        "target_horizontal_cm": 0.53,
        "target_vertical_cm": 0.22,
        "max_point_cm": 2.10,
        "mean_point_cm": 1.37,
    },
    "c2c": {
        "label": "Nav. sensors + C2C",
        "target_mean_cm": 1.72,
        "target_horizontal_cm": 1.34,
        "target_vertical_cm": 0.82,
        "max_point_cm": 3.02,
        "mean_point_cm": 2.07,
    },
}
HAUSDORFF: Json = {"mean_cm": 1.25, "sd_cm": 0.82, "below_2cm": 0.85, "below_3cm": 0.95}


def _ours(row: Json) -> Json:
    t, p = row.get("targets") or {}, row.get("overlap") or {}
    return {
        "target_mean_cm": t.get("mean_cm"),
        "target_horizontal_cm": t.get("horizontal_cm"),
        "target_vertical_cm": t.get("vertical_cm"),
        "max_point_cm": p.get("max_cm"),
        "mean_point_cm": p.get("mean_cm"),
    }


def compare(registration: Json | None) -> Json | None:
    """Our figures (``report.json``'s ``registration`` table: target statistics
    against the target-based reference, scan point statistics from the overlaps)
    beside the paper's: Table 1 per method, and the nav + C2C cloud's Hausdorff-style
    distances. None when the report has no registration."""
    if registration is None:
        return None
    rows = {r["method"]: r for r in registration.get("vs_reference", [])}
    table = [
        {"method": m, "label": paper["label"], "ours": _ours(rows[m]), "paper": paper}
        for m, paper in TABLE1.items()
        if m in rows
    ]
    h = (rows.get("c2c") or {}).get("hausdorff")
    ours_h = None
    if h is not None:
        ours_h = {k: h.get(k) for k in HAUSDORFF}
    return {"table1": table, "hausdorff": {"ours": ours_h, "paper": HAUSDORFF}}
