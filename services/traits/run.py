"""A registered survey as the traits job reads it: ``RUN_DIR/mission.db`` (read-only,
through :func:`common.missionlog.read_run`), the field its plan was made for, the
field book, ``RUN_DIR/registered.laz`` (``phenorover register``'s merged cloud, field
frame, each point's scan its point source id), the scanner position of each scan
(the poses in ``RUN_DIR/registered.e57``; read when the traits are computed) and the
survey's date.

The date, first that applies: ``--date``; the mission's ``created_ns`` as a UTC date
when it is a wall-clock stamp (from year 2000 on); for a simulated run, whose clock
starts at zero and has no calendar, the ``[services.sim.world.trial] date`` of the
run's manifest copy ``RUN_DIR/manifest.toml``: the date the deployment's author wrote
for the simulated trial (their configuration, not a measurement nor the simulator's
truth); else none (an empty date).

Every problem with the input raises :class:`RunError` with one line naming the file.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import logging
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import numpy.typing as npt

from common.arrays import F64
from common.field import Field, FieldError, FieldLayout, build_field, load_field
from common.field_model import PlotRecord
from common.fieldbook import records
from common.messages.plan import PlanResult
from common.missionlog import MissionLogError, read_run

log = logging.getLogger("phenorover.traits")

CLOUD = "registered.laz"
SCANS = "registered.e57"  # the same scans with their poses: where each was seen from
MANIFEST_COPY = "manifest.toml"  # services/mission/runfiles.py keeps it there
# 2000-01-01T00:00:00Z: a mission stamp below is a simulated clock's, not a date
WALL_CLOCK_FROM_NS = 946_684_800 * 10**9


class RunError(ValueError):
    """The run folder cannot be measured; the message names the file and the cause."""


# one plot's field-book entry: plot id, row, column, entry, rep
Record = PlotRecord


def field_records(layout: FieldLayout, field: Field, db: Path) -> list[Record]:
    """The field book: one record per plot, in plot order (:mod:`common.fieldbook`;
    its defaults when the field has none). Raises RunError when the plan's book does
    not match its field."""
    try:
        return records(layout, field)
    except FieldError as exc:
        raise RunError(f"{db}: the plan's field book: {exc}") from None


@dataclasses.dataclass(frozen=True)
class RunInput:
    """What the traits of one run are computed from. ``date``: ``YYYY-MM-DD`` or ""
    (unknown); ``date_source`` says where it came from."""

    run_dir: Path
    mission: dict[str, Any]
    layout: FieldLayout
    field: Field
    records: list[Record]
    date: str
    date_source: str
    cloud: F64
    # each point's scan (N,): where it was seen from is read from registered.e57
    # when the traits are computed (:func:`read_views`), after the run is checked;
    # None, or no registered.e57: the voxel volume counts only the voxels hit
    source: npt.NDArray[np.int64] | None = None

    def scan_views(self) -> Views | None:
        """Where each point was seen from (see :func:`read_views`)."""
        return None if self.source is None else read_views(self.run_dir, self.source)


@dataclasses.dataclass(frozen=True)
class Views:
    """Each point's scan ``source`` (N,) and each scan's scanner position
    ``origins`` (S, 3)."""

    source: npt.NDArray[np.int64]
    origins: F64


def plan_field(plan: PlanResult, db: Path) -> Field:
    """The field the plan was made for: its layout's, else its field file's (a
    GeoJSON field's plots need not be a regular grid), whichever has the plan's plot
    footprints (a plan on a measured crop planned on other boxes). Raises RunError."""
    try:
        boxes = plan.plot_footprints()
    except ValueError as exc:
        raise RunError(f"{db}: the plan's plot boxes: {exc}") from None
    for make in (lambda: build_field(plan.layout), lambda: load_field(plan.field)[1]):
        try:
            f = make()
        except (FieldError, OSError):
            continue
        if f.plot_boxes.shape == boxes.shape and np.allclose(f.plot_boxes, boxes, atol=1e-6):
            return f
    raise RunError(
        f"{db}: the plan's {len(boxes)} plot boxes are neither its layout's nor those of "
        f"its field {plan.field!r} (is the field file here?)"
    )


def survey_date(run_dir: Path, created_ns: int, given: str | None) -> tuple[str, str]:
    """(date, where it came from); see the module docstring. Raises RunError for a
    ``given`` date that is not ``YYYY-MM-DD``."""
    if given:
        try:
            return dt.date.fromisoformat(given).isoformat(), "--date"
        except ValueError:
            raise RunError(f"--date {given!r}: expected YYYY-MM-DD") from None
    if created_ns >= WALL_CLOCK_FROM_NS:
        stamp = dt.datetime.fromtimestamp(created_ns / 1e9, tz=dt.UTC)
        return stamp.date().isoformat(), "mission clock (UTC)"
    path = run_dir / MANIFEST_COPY
    if not path.is_file():
        return "", ""
    from common.config import ConfigError, read_toml

    try:
        raw: Any = read_toml(path)
    except ConfigError as exc:
        log.warning("no survey date: %s", exc)
        return "", ""
    for key in ("services", "sim", "world", "trial", "date"):
        raw = raw.get(key) if isinstance(raw, dict) else None
    if isinstance(raw, dt.date | str):
        try:
            date = raw if isinstance(raw, dt.date) else dt.date.fromisoformat(raw)
        except ValueError:
            log.warning("no survey date: %s: trial date %r is not YYYY-MM-DD", path, raw)
            return "", ""
        return date.isoformat()[:10], f"{path.name} [services.sim.world.trial] date"
    return "", ""


def read_views(run: Path, source: npt.NDArray[np.int64]) -> Views | None:
    """Where each point was seen from: ``source`` (the cloud's point source ids, its
    scan indices) and the scanner positions of ``registered.e57``'s poses; None (and
    a line in the log) when the file is missing or does not match the cloud."""
    from common.pointcloud import CloudIOError, read_e57_positions

    path = run / SCANS
    try:
        origins = read_e57_positions(path) if path.is_file() else None
    except CloudIOError as exc:
        log.info("voxel volume without occlusion: %s", exc)
        return None
    if origins is None:
        log.info("voxel volume without occlusion: no %s beside the cloud", path)
        return None
    if len(origins) == 0 or source.max() >= len(origins) or not np.isfinite(origins).all():
        log.info(
            "voxel volume without occlusion: %s: %d scan poses for scans 0-%d",
            path, np.isfinite(origins).all(axis=1).sum(), source.max(),
        )  # fmt: skip
        return None
    return Views(source, origins)


def read_cloud(path: Path) -> tuple[F64, npt.NDArray[np.int64]]:
    """The (N, 3) field-frame points of a LAZ/LAS file and their point source ids
    (N,); raises RunError."""
    import laspy

    if not path.is_file():
        raise RunError(
            f"{path}: no registered cloud here; run `phenorover register {path.parent}` first"
        )
    try:
        las = laspy.read(str(path))
        xyz = np.column_stack([las.x, las.y, las.z]).astype(np.float64)
        source = np.asarray(las.point_source_id, dtype=np.int64)
    except (laspy.LaspyException, OSError, ValueError, EOFError) as exc:
        raise RunError(f"{path}: not a readable LAZ file: {' '.join(str(exc).split())}") from None
    if len(xyz) == 0:
        raise RunError(f"{path}: the cloud holds no points")
    if not np.isfinite(xyz).all():
        raise RunError(f"{path}: the cloud holds non-finite coordinates")
    return xyz, source


def load_run(run_dir: str | Path, date: str | None = None) -> RunInput:
    """Read a run folder (see the module docstring); raises RunError."""
    run = Path(run_dir)
    try:
        db, _, mission = read_run(run)
    except MissionLogError as exc:
        raise RunError(str(exc)) from None
    text = str(mission.pop("plan_json") or "")
    if not text:
        raise RunError(f"{db}: the mission holds no plan, so no field to cut the cloud by")
    try:
        plan = msgspec.json.decode(text, type=PlanResult)
    except msgspec.DecodeError as exc:
        raise RunError(f"{db}: mission.plan_json is not a plan: {exc}") from None
    field = plan_field(plan, db)
    when, source = survey_date(run, int(mission.get("created_ns") or 0), date)
    book = field_records(plan.layout, field, db)
    cloud, ids = read_cloud(run / CLOUD)
    return RunInput(run, mission, plan.layout, field, book, when, source, cloud, ids)
