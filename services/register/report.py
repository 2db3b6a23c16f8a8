"""The survey report: the paper's tables from a stored mission log and a registration.

:func:`build_report` takes only what is stored (the mission log read by
:mod:`.runlog`) and the registration's report (:class:`.outcome.RegistrationReport`),
so a report can be remade from a run folder without running the mission again.
:func:`.report_md.markdown` renders it as ``report.md``; ``report.json`` is the same dict.

Tables:

- navigation: the plan (locations, tour under BR or AHA navigation, its length and
  the nearest-neighbour baseline) and what the survey did (scans done, failed,
  skipped, survey time);
- stationary errors per scan location (paper Figures 21-22): distance from the
  planned point to the recorded mean position, heading error, the SD of the pose
  over the scan, the inclinometer's pitch and roll;
- registration (the metrics of the paper's Table 1): target statistics and point
  errors of navigation-only, navigation + C2C and target-based registration against
  the target-based reference; each one's scan point statistics as SCENE reports them
  (overlap residuals, :func:`.metrics.overlap_stats`); the Hausdorff-style distances
  of each cloud to the target-based cloud (mean, SD, share below 2 and 3 cm, per axis).

The report holds our own figures only: the paper's figures beside them, and errors
against a simulator's truth, are the evaluation's (``phenorover eval register``).

Lengths in the tables are centimetres, angles degrees; report.json keeps SI units
(m, rad) where it copies the registration report.
"""

from __future__ import annotations

import math
from typing import Any

import msgspec

from common.geo import wrap_angle
from services.register.outcome import MethodReport, RegistrationReport
from services.register.runlog import RunData

Json = dict[str, Any]
METHODS = (("navigation", "Nav. sensors only"), ("c2c", "Nav. sensors + C2C"))


def _cm(v: float | None) -> float | None:
    return None if v is None or not math.isfinite(v) else round(100.0 * v, 3)


def navigation_table(run: RunData) -> Json:
    steps = run.steps
    tour = None if run.plan is None else run.plan.tour
    ended = [s.ended_ns for s in steps if s.ended_ns is not None]
    created = int(run.mission["created_ns"])  # type: ignore[call-overload]
    return {
        "mission": run.mission["id"],
        "field": run.mission["field"],
        "state": run.mission["state"],
        "locations": len(steps),
        "done": sum(s.status == "done" for s in steps),
        "failed": sum(s.status == "failed" for s in steps),
        "skipped": sum(s.status == "skipped" for s in steps),
        "navigation": None if tour is None else tour.nav,
        "route_m": None if tour is None else tour.length,
        "nearest_neighbour_m": None if tour is None else tour.nn_length,
        "survey_s": (max(ended) - created) / 1e9 if ended else None,
        "has_altitude": run.has_altitude,
    }


def stationary_table(run: RunData) -> list[Json]:
    rows = []
    for s in run.steps:
        row: Json = {"scan_id": s.scan_id, "location": s.cand_id, "status": s.status}
        row["planned"] = [s.x, s.y, s.yaw]
        if s.mean_x is not None and s.mean_y is not None:
            row["distance_to_planned_cm"] = _cm(math.hypot(s.mean_x - s.x, s.mean_y - s.y))
            row["mean"] = [s.mean_x, s.mean_y, s.mean_yaw]
        if s.mean_yaw is not None and s.yaw is not None:
            row["heading_error_deg"] = math.degrees(wrap_angle(s.mean_yaw - s.yaw))
        for k in ("sd_x", "sd_y", "sd_z"):
            v = getattr(s, k)
            row[f"{k}_cm"] = _cm(v)
        row["sd_yaw_deg"] = None if s.sd_yaw is None else math.degrees(s.sd_yaw)
        row["pitch_deg"] = None if s.pitch is None else math.degrees(s.pitch)
        row["roll_deg"] = None if s.roll is None else math.degrees(s.roll)
        if s.reason:
            row["reason"] = s.reason
        rows.append(row)
    return rows


def _method_row(name: str, label: str, m: MethodReport) -> Json:
    t, p, c = m.targets_vs_reference, m.points_vs_reference, m.cloud_vs_reference
    row: Json = {"method": name, "label": label}
    row["targets"] = (
        None
        if t is None or t.count == 0
        else {
            "count": t.count,
            "mean_cm": _cm(t.mean),
            "horizontal_cm": _cm(t.horizontal),
            "vertical_cm": _cm(t.vertical),
        }
    )
    row["points"] = (
        None
        if p is None or p.count == 0
        else {
            "count": p.count,
            "max_cm": _cm(p.max),
            "mean_cm": _cm(p.mean),
            "per_scan_mean_cm": [_cm(v) for v in p.per_scan_mean],
        }
    )
    o = m.overlap
    row["overlap"] = (
        None
        if o is None or o.count == 0
        else {
            "radius_cm": _cm(o.radius),
            "pairs": len(o.pairs),
            "count": o.count,
            "max_cm": _cm(o.max),
            "mean_cm": _cm(o.mean),
        }
    )
    row["hausdorff"] = (
        None
        if c is None
        else {
            "mean_cm": _cm(c.mean),
            "sd_cm": _cm(c.sd),
            "max_cm": _cm(c.max),
            "below_2cm": c.below_2cm,
            "below_3cm": c.below_3cm,
            "axis_mean_cm": [_cm(v) for v in c.axis_mean],
            "axis_sd_cm": [_cm(v) for v in c.axis_sd],
        }
    )
    return row


def registration_table(rep: RegistrationReport) -> Json:
    solved = sum(s.target_solved for s in rep.scans)
    methods = [*METHODS, ("target_based", "Target-based")]
    if rep.c2c_without_targets is not None:
        # the spheres joined the C2C pose graph: also what the clouds alone give
        methods.insert(2, ("c2c_without_targets", "Nav. sensors + C2C, spheres left out"))
    return {
        "scans": len(rep.scans),
        "reference_solved_scans": solved,
        "reference_complete": solved == len(rep.scans),
        "spheres_per_scan": [s.spheres for s in rep.scans],
        "pairs_kept": sum(p.kept for p in rep.pairs),
        "pairs_tried": len(rep.pairs),
        "time_s": rep.time_s,
        "vs_reference": [_method_row(n, lab, getattr(rep, n)) for n, lab in methods],
    }


def build_report(run: RunData, rep: RegistrationReport | None, outputs: Json) -> Json:
    """The report as a JSON-able dict (see the module docstring); ``rep`` None when the
    mission has no registration (no done scan)."""
    return {
        "navigation": navigation_table(run),
        "stationary": stationary_table(run),
        "registration": None if rep is None else registration_table(rep),
        "registration_detail": None if rep is None else msgspec.to_builtins(rep),
        "targets": target_sites(run),
        "outputs": outputs,
    }


def target_sites(run: RunData) -> Json:
    """How the spheres were placed, as far as the survey knows: the sites the field
    file lists (where the surveyor set them out), or none listed."""
    sites = [] if run.plan is None else [list(t) for t in run.plan.layout.targets]
    how = (
        f"{len(sites)} sites listed in the field file ({run.plan.field if run.plan else '?'})"
        if sites
        else "no sites listed in the field file: spheres found in the scans only"
    )
    return {"placement": how, "sites": sites}
