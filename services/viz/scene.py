"""Messages -> rerun archetypes: the dashboard's pure core (no Zenoh, no sinks).

Every function returns :class:`Entry` values (entity path, archetype, static) that
the shell logs on the current time. Entity tree, all in the ``field`` frame (metres,
z up):

- ``field/plots``, ``field/cells`` (coloured by how many selected scans see them),
  ``field/candidates``, ``field/selected``
- ``route/legs``
- ``robot/estimate`` (a transform with a body box below it), ``robot/estimate/lidar``,
  ``robot/trail/<k>`` (coloured by cross-track error)
- ``gnss/fix1``, ``gnss/fix2``, ``gnss/heading``
- ``errors/cross_track_m``, ``errors/heading_deg``; ``mission/log``,
  ``mission/scans_done``; ``scanner/log``, ``scanner/progress``
- ``clouds/scan_<id>``, ``clouds/registered``; ``field/traits/<trait>`` (:mod:`.traits_view`)
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import rerun as rr

from common.arrays import F64, I64, U8
from common.field import Field
from common.geo import FieldFrame
from common.messages.base import BatteryState, LaserScan
from common.messages.gnss import FixType, GnssHeading, NavSatFix
from common.messages.mission import MissionEvent, MissionState
from common.messages.nav import NavProgress
from common.messages.plan import PlanResult
from common.messages.scan import ScannerStatus
from common.robot import LidarMount, Robot

ROUTE_Z = 0.02  # lines drawn just above the ground so the terrain does not hide them

GREY = (150, 150, 150)
ORANGE = (255, 140, 0)
BLUE = (60, 130, 255)
GREEN = (40, 200, 70)
RED = (230, 40, 40)
YELLOW = (240, 210, 40)
# cells by number of selected scans that see them: 0, 1, 2, 3+
VIEW_COLOURS = np.array(
    [[230, 40, 40, 200], [240, 210, 40, 120], [140, 220, 90, 100], [40, 170, 60, 90]],
    dtype=np.uint8,
)
LEVELS = {"info": "INFO", "warning": "WARN", "error": "ERROR"}


@dataclasses.dataclass(frozen=True)
class Entry:
    """One thing to log: ``item`` is a rerun archetype."""

    path: str
    item: Any
    static: bool = False


def blueprint() -> Any:
    """The dashboard's layout: the 3D scene beside the error plots, the scanner's
    progress and the mission log."""
    import rerun.blueprint as rrb

    # the traits' boxes get a tab of their own: the survey's cells and clouds hide them
    survey = ["/field/**", "- /field/traits/**", "/route/**", "/robot/**", "/gnss/**", "/clouds/**"]
    scene3d = rrb.Spatial3DView(origin="/", contents=survey, name="field")
    mine = ["/field/traits/**", "/field/plots"]
    traits = rrb.Spatial3DView(origin="/", contents=mine, name="traits")
    side = rrb.Vertical(
        rrb.TimeSeriesView(origin="/errors", name="cross-track (m), heading error (deg)"),
        rrb.TimeSeriesView(
            contents=["/scanner/progress", "/mission/scans_done"], name="scanner, scans"
        ),
        rrb.TextLogView(contents=["/mission/log", "/scanner/log"], name="mission log"),
    )
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Tabs(scene3d, traits), side, column_shares=[3, 2]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed"),
    )


def body(
    path: str, robot: Robot, colour: tuple[int, ...], solid: bool = False, label: str = ""
) -> Entry:
    """``robot``'s footprint as a box standing on the ground under the transform at
    ``path``'s parent (static), named ``label`` in the view when given."""
    fp = robot.footprint
    half = [[fp.length / 2, fp.width / 2, fp.height / 2]]
    box = rr.Boxes3D(
        half_sizes=half,
        centers=[[0.0, 0.0, fp.height / 2]],
        colors=[colour],
        fill_mode="solid" if solid else None,
        labels=[label] if label else None,
    )
    return Entry(path, box, static=True)


def world(robot: Robot) -> list[Entry]:
    """What never changes: the up axis and the robot's body under its estimate."""
    return [
        Entry("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True),
        body("robot/estimate/body", robot, BLUE),
    ]


def plan_entries(plan: PlanResult) -> list[Entry]:
    """The field, candidates, selected locations and route of ``plan`` (static)."""
    boxes = np.asarray(plan.plot_boxes.numpy(), dtype=np.float64).reshape(-1, 6)
    cands = plan.candidates
    by_id = {c.id: c for c in cands}
    sel = [by_id[i] for i in plan.selected if i in by_id]
    legs = [[[g.x0, g.y0, ROUTE_Z], [g.x1, g.y1, ROUTE_Z]] for g in plan.legs]
    leg_colours = [ORANGE if g.scan_id is not None else BLUE for g in plan.legs]
    return [
        Entry(
            "field/plots",
            rr.Boxes3D(mins=boxes[:, :3], sizes=boxes[:, 3:] - boxes[:, :3], colors=[GREEN]),
            static=True,
        ),
        Entry(
            "field/candidates",
            rr.Points3D([[c.x, c.y, 0.0] for c in cands], colors=[GREY], radii=[0.06], labels=None),
            static=True,
        ),
        Entry(
            "field/selected",
            rr.Points3D(
                [[c.x, c.y, 0.0] for c in sel],
                colors=[ORANGE],
                radii=[0.15],
                labels=[str(c.id) for c in sel],
            ),
            static=True,
        ),
        Entry(
            "route/origin",
            rr.Points3D([[plan.origin[0], plan.origin[1], 0.0]], colors=[RED], radii=[0.2]),
            static=True,
        ),
        Entry("route/legs", rr.LineStrips3D(legs, colors=leg_colours, radii=[0.04]), static=True),
    ]


def field_of(plan: PlanResult, fields: list[Field]) -> Field | None:
    """The first of ``fields`` whose plot boxes are the plan's (cells need the Field)."""
    boxes = np.asarray(plan.plot_boxes.numpy(), dtype=np.float64).reshape(-1, 6)
    for f in fields:
        if f.plot_boxes.shape == boxes.shape and np.allclose(f.plot_boxes, boxes, atol=1e-6):
            return f
    return None


def cell_entry(field: Field, views: I64) -> Entry:
    c = field.cell_boxes
    colours = VIEW_COLOURS[np.minimum(views, len(VIEW_COLOURS) - 1)]
    return Entry(
        "field/cells",
        rr.Boxes3D(mins=c[:, :3], sizes=c[:, 3:] - c[:, :3], colors=colours, fill_mode="solid"),
        static=True,
    )


def pose(path: str, x: float, y: float, z: float, yaw: float) -> Entry:
    return Entry(
        path,
        rr.Transform3D(
            translation=[x, y, z], rotation=rr.RotationAxisAngle(axis=[0, 0, 1], radians=yaw)
        ),
    )


def error_colour(err: F64, full_scale: float = 0.1) -> U8:
    """Green at 0 through yellow to red at ``full_scale`` metres of |error|."""
    t = np.clip(np.abs(err) / full_scale, 0.0, 1.0)
    r = np.where(t < 0.5, 2 * t * 255 + (1 - 2 * t) * 40, 230)
    g = np.where(t < 0.5, 200, (2 - 2 * t) * 200)
    return np.stack([r, g, np.full_like(t, 40.0)], axis=-1).astype(np.uint8)


class Trail:
    """The driven path, split into chunks of ``chunk`` points so each log call
    re-sends only the growing chunk (a recording stays linear in trail length)."""

    def __init__(self, step_m: float, chunk: int = 200) -> None:
        self.step, self.chunk = step_m, chunk
        self.points: list[tuple[float, float, float]] = []  # x, y, cross-track

    def add(self, x: float, y: float, cross_track: float) -> list[Entry]:
        if self.points:
            px, py, _ = self.points[-1]
            if math.hypot(x - px, y - py) < self.step:
                return []
        self.points.append((x, y, cross_track))
        k = (len(self.points) - 1) // self.chunk
        # a chunk starts at its predecessor's last point, so the line has no gaps
        part = np.array(self.points[max(k * self.chunk - 1, 0) :])
        xyz = np.column_stack([part[:, :2], np.full(len(part), ROUTE_Z * 2)])
        return [
            Entry(
                f"robot/trail/{k:04d}",
                rr.Points3D(xyz, colors=error_colour(part[:, 2]), radii=[0.03]),
            )
        ]


def fix_entry(fix: NavSatFix, frame: FieldFrame) -> Entry:
    x, y, z = frame.wgs84_to_field(fix.latitude, fix.longitude, fix.altitude)
    colour = {FixType.FIX: GREEN, FixType.FLOAT: YELLOW}.get(fix.fix_type, RED)
    return Entry(
        f"gnss/fix{fix.antenna}",
        rr.Points3D(
            [[float(x), float(y), float(z)]],
            colors=[colour],
            radii=[0.05],
            labels=[f"{fix.antenna}: {fix.fix_type.name}"],
        ),
    )


def heading_entry(h: GnssHeading, x: float, y: float) -> Entry:
    """The GNSS compass heading as a 1 m arrow from (x, y)."""
    return Entry(
        "gnss/heading",
        rr.Arrows3D(
            origins=[[x, y, 0.6]],
            vectors=[[math.cos(h.yaw), math.sin(h.yaw), 0.0]],
            colors=[GREEN if h.valid else RED],
        ),
    )


def lidar_entry(scan: LaserScan, mount: LidarMount) -> Entry:
    """The planar scan's returns in base_link (below ``robot/estimate``), from a lidar
    at ``mount``."""
    r = np.asarray(scan.ranges.numpy(), dtype=np.float64).ravel()
    a = mount.yaw_rad + scan.angle_min + scan.angle_increment * np.arange(len(r))
    ok = np.isfinite(r) & (r >= scan.range_min) & (r <= scan.range_max)
    xyz = np.column_stack(
        [
            mount.x + r[ok] * np.cos(a[ok]),
            mount.y + r[ok] * np.sin(a[ok]),
            np.full(ok.sum(), mount.z),
        ]
    )
    return Entry("robot/estimate/lidar", rr.Points3D(xyz, colors=[RED], radii=[0.02]))


def progress_entries(p: NavProgress) -> list[Entry]:
    return [
        Entry("errors/cross_track_m", rr.Scalars(p.cross_track)),
        Entry("errors/heading_deg", rr.Scalars(math.degrees(p.heading_error))),
    ]


def battery_entry(b: BatteryState) -> Entry:
    """The charge the base reports, in percent, as a time series."""
    return Entry("robot/battery_pct", rr.Scalars(100.0 * b.percentage))


def state_entries(prev: MissionState | None, s: MissionState) -> list[Entry]:
    out = [Entry("mission/scans_done", rr.Scalars(float(s.scans_done)))]
    if prev is None or (prev.mission, prev.phase, prev.detail) != (s.mission, s.phase, s.detail):
        text = f"{s.mission}: {s.phase.value}" + (f" ({s.detail})" if s.detail else "")
        text += f", {s.scans_done}/{s.scans_total} scans"
        out.append(Entry("mission/log", rr.TextLog(text, level="DEBUG")))
    return out


def event_entry(e: MissionEvent) -> Entry:
    return Entry("mission/log", rr.TextLog(e.text, level=LEVELS.get(e.level, "INFO")))


def scanner_entries(prev: ScannerStatus | None, s: ScannerStatus) -> list[Entry]:
    out = [Entry("scanner/progress", rr.Scalars(s.progress))]
    if prev is None or (prev.state, prev.scan_id) != (s.state, s.scan_id):
        text = f"scan {s.scan_id}: {s.state.value}" + (f" ({s.error})" if s.error else "")
        level = "ERROR" if s.error else "INFO"
        out.append(Entry("scanner/log", rr.TextLog(text, level=level)))
    return out


def height_colours(z: F64) -> U8:
    """Brown at the ground to green at the top of the cloud (robust to outliers)."""
    lo, hi = np.percentile(z, [2, 98]) if len(z) else (0.0, 1.0)
    t = np.clip((z - lo) / max(hi - lo, 1e-6), 0.0, 1.0)[:, None]
    ground, top = np.array([140, 100, 60]), np.array([60, 200, 60])
    out: U8 = (ground + t * (top - ground)).astype(np.uint8)
    return out


def cloud_entry(path: str, points: F64) -> Entry:
    return Entry(path, rr.Points3D(points, colors=height_colours(points[:, 2]), radii=[0.01]))
