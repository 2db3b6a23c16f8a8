"""``report.md``: the survey report (:mod:`.report`) as Markdown tables, lengths in
centimetres and angles in degrees."""

from __future__ import annotations

from typing import Any

Json = dict[str, Any]


def markdown(report: Json, figures: list[str]) -> str:
    """``report.md``: the tables and the figures (paths relative to the report)."""
    nav = report["navigation"]
    lines = [
        f"# Survey report: {nav['mission']}",
        "",
        f"Field `{nav['field']}`, mission {nav['state']}.",
        "",
        *_navigation(nav),
        "",
        *_stationary(report["stationary"]),
        "",
        "## Registration",
        "",
    ]
    if report.get("targets"):
        lines += [f"Sphere targets: {report['targets']['placement']}.", ""]
    reg = report["registration"]
    lines += ["No scan was done: nothing to register."] if reg is None else _registration(reg)
    if not nav["has_altitude"]:
        lines += [
            "",
            "Note: the mission log records no altitude (the navigation pose's z is 0 "
            "throughout), so navigation-only placement is off vertically by the terrain "
            "height and only cloud-to-cloud refinement places scans in height.",
        ]
    outs = report["outputs"]
    if outs:
        lines += ["", "## Outputs", ""] + [f"- {k}: `{v}`" for k, v in outs.items() if v]
    if figures:
        lines += ["", "## Figures", ""] + [f"![{f}]({f})" for f in figures]
    return "\n".join(lines) + "\n"


def _f(v: Any, digits: int = 2) -> str:
    return "–" if v is None else f"{v:.{digits}f}"


def _navigation(nav: Json) -> list[str]:
    return [
        "## Navigation",
        "",
        "| scan locations | done | failed | skipped | navigation | route (m) "
        "| nearest-neighbour route (m) | survey time (s) |",
        "|---|---|---|---|---|---|---|---|",
        f"| {nav['locations']} | {nav['done']} | {nav['failed']} | {nav['skipped']} "
        f"| {nav['navigation'] or '–'} | {_f(nav['route_m'], 1)} "
        f"| {_f(nav['nearest_neighbour_m'], 1)} | {_f(nav['survey_s'], 0)} |",
    ]


def _stationary(rows: list[Json]) -> list[str]:
    lines = [
        "## Stationary errors per scan location",
        "",
        "Recorded navigation pose over each scan against the planned point.",
        "",
        "| scan | location | status | distance to planned (cm) | heading error (deg) "
        "| SD x (cm) | SD y (cm) | SD heading (deg) | pitch (deg) | roll (deg) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['scan_id']} | {r['location']} | {r['status']} "
            f"| {_f(r.get('distance_to_planned_cm'))} | {_f(r.get('heading_error_deg'))} "
            f"| {_f(r.get('sd_x_cm'))} | {_f(r.get('sd_y_cm'))} | {_f(r.get('sd_yaw_deg'), 3)} "
            f"| {_f(r.get('pitch_deg'))} | {_f(r.get('roll_deg'))} |"
        )
    return lines


def _registration(reg: Json) -> list[str]:
    lines = [
        f"{reg['scans']} scans registered in {reg['time_s']:.1f} s; "
        f"{reg['pairs_kept']} of {reg['pairs_tried']} scan pairs used by the pose graph; "
        f"spheres found per scan: {reg['spheres_per_scan']}; the target-based reference "
        f"fixes {reg['reference_solved_scans']} of {reg['scans']} scans"
        + (
            "."
            if reg["reference_complete"]
            else " (the others keep their navigation "
            "pose, so errors against it understate the truth)."
        ),
        "",
        "Against the target-based reference (cm):",
        "",
        *_method_lines(reg["vs_reference"]),
        "",
        "Scan point statistics, as SCENE reports them (each scan's points against the "
        "nearest point of every overlapping scan, within the search radius; no "
        "reference needed):",
        "",
        "| method | overlapping pairs | max point error (cm) | mean point error (cm) |",
        "|---|---|---|---|",
        *[
            f"| {r['label']} | {o['pairs']} | {_f(o['max_cm'])} | {_f(o['mean_cm'])} |"
            for r in reg["vs_reference"]
            if (o := r.get("overlap"))
        ],
        "",
        "Cloud to the target-based cloud (Hausdorff-style nearest-neighbour distances):",
        "",
        "| cloud | mean (cm) | SD (cm) | < 2 cm | < 3 cm | dX mean/SD | dY mean/SD | dZ mean/SD |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in reg["vs_reference"]:
        h = r["hausdorff"]
        if h is None:
            continue
        ax = [f"{_f(m)} / {_f(s)}" for m, s in zip(h["axis_mean_cm"], h["axis_sd_cm"], strict=True)]
        lines.append(
            f"| {r['label']} | {_f(h['mean_cm'])} | {_f(h['sd_cm'])} "
            f"| {h['below_2cm']:.0%} | {h['below_3cm']:.0%} | {' | '.join(ax)} |"
        )
    return lines


def _method_lines(rows: list[Json]) -> list[str]:
    out = [
        "| method | target mean | horizontal | vertical | max point distance "
        "| mean point distance |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        t, p = r["targets"] or {}, r["points"] or {}
        cells = [
            r["label"],
            _f(t.get("mean_cm")),
            _f(t.get("horizontal_cm")),
            _f(t.get("vertical_cm")),
            _f(p.get("max_cm")),
            _f(p.get("mean_cm")),
        ]
        out.append("| " + " | ".join(cells) + " |")
    return out
