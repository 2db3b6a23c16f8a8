"""The mission log's schema and its read-only reader: every step of a survey in SQLite,
``runs/<mission>/mission.db``. The mission service writes it (``services/mission/log.py``,
one transaction per change); registration and anything else only read it, through
:func:`read_log`, which opens it with SQLite's ``mode=ro`` so a reader that fails or is
killed can never lose or corrupt it.

Schema:

- ``mission``: one row: ``id``, ``field``, ``created_ns``, ``plan_json`` (the plan
  the survey follows, verbatim), ``state`` (running, paused, done, aborted).
- ``steps``: one row per scan location in tour order: ``idx``, ``scan_id``,
  ``cand_id``, planned ``x``, ``y``, ``yaw``; ``status`` (pending, driving, scanning,
  done, failed, skipped); ``attempts``; ``file`` (the scan on the scanner's card);
  ``started_ns``/``ended_ns`` (scan start and end, clock of the mission service);
  pose statistics over the scan from the navigation estimate: ``mean_x``,
  ``mean_y``, ``mean_z``, ``mean_yaw``, ``sd_x``, ``sd_y``, ``sd_z``, ``sd_yaw``
  (metres, radians); the inclinometer's ``pitch`` and ``roll`` (radians);
  ``nav_roll`` and ``nav_pitch``, the mean tilt navigation put the antennas' lever arms
  through over the scan (radians; NULL: a planar estimate, antennas taken upright);
  ``pose_x``, ``pose_y``, ``pose_z``, ``pose_yaw``: the navigation pose the scan is
  placed with (metres, radians), by default the estimate at the scan's end (see
  ``[services.mission] scan_pose``; NULL in a log written before the columns
  existed, whose readers take the means);
  ``reason`` for a failed or skipped step.
- ``events``: ``stamp_ns``, ``level`` (info, warning, error), ``text``.
"""

from __future__ import annotations

import dataclasses
import sqlite3
from pathlib import Path
from typing import Any

SCHEMA = """
CREATE TABLE IF NOT EXISTS mission (
    id TEXT PRIMARY KEY, field TEXT NOT NULL, created_ns INTEGER NOT NULL,
    plan_json TEXT NOT NULL, state TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS steps (
    idx INTEGER PRIMARY KEY, scan_id INTEGER NOT NULL, cand_id INTEGER NOT NULL,
    x REAL NOT NULL, y REAL NOT NULL, yaw REAL,
    status TEXT NOT NULL DEFAULT 'pending', attempts INTEGER NOT NULL DEFAULT 0,
    file TEXT, started_ns INTEGER, ended_ns INTEGER,
    mean_x REAL, mean_y REAL, mean_z REAL, mean_yaw REAL,
    sd_x REAL, sd_y REAL, sd_z REAL, sd_yaw REAL, pitch REAL, roll REAL, reason TEXT,
    nav_roll REAL, nav_pitch REAL,
    pose_x REAL, pose_y REAL, pose_z REAL, pose_yaw REAL
);
CREATE TABLE IF NOT EXISTS events (
    stamp_ns INTEGER NOT NULL, level TEXT NOT NULL, text TEXT NOT NULL
);
"""

STEP_STATES = ("pending", "driving", "scanning", "done", "failed", "skipped")
FINISHED = ("done", "failed", "skipped")
MISSION_COLUMNS = ("id", "field", "created_ns", "plan_json", "state")
Event = tuple[int, str, str]


class MissionLogError(ValueError):
    """A mission log that cannot be read; the message names the file and the cause."""


@dataclasses.dataclass(frozen=True)
class Step:
    """One row of ``steps`` (see the module docstring for the columns' meaning)."""

    idx: int
    scan_id: int
    cand_id: int
    x: float
    y: float
    yaw: float | None
    status: str
    attempts: int
    file: str | None = None
    started_ns: int | None = None
    ended_ns: int | None = None
    mean_x: float | None = None
    mean_y: float | None = None
    mean_z: float | None = None
    mean_yaw: float | None = None
    sd_x: float | None = None
    sd_y: float | None = None
    sd_z: float | None = None
    sd_yaw: float | None = None
    pitch: float | None = None
    roll: float | None = None
    reason: str | None = None
    nav_roll: float | None = None
    nav_pitch: float | None = None
    pose_x: float | None = None
    pose_y: float | None = None
    pose_z: float | None = None
    pose_yaw: float | None = None


# columns added since the first schema: (name, SQL type), added to an older log that
# a mission resumes
ADDED_COLUMNS = (
    ("nav_roll", "REAL"),
    ("nav_pitch", "REAL"),
    ("pose_x", "REAL"),
    ("pose_y", "REAL"),
    ("pose_z", "REAL"),
    ("pose_yaw", "REAL"),
)


@dataclasses.dataclass(frozen=True)
class LogData:
    """Everything in one mission log: the mission row (None when the table is empty),
    the steps in tour order and the events in the order they were written."""

    mission: dict[str, Any] | None
    steps: list[Step]
    events: list[Event]


def select_mission(db: sqlite3.Connection) -> dict[str, Any] | None:
    row = db.execute(f"SELECT {', '.join(MISSION_COLUMNS)} FROM mission").fetchone()
    return None if row is None else dict(zip(MISSION_COLUMNS, row, strict=True))


def select_steps(db: sqlite3.Connection) -> list[Step]:
    """Raises TypeError when the table's columns are not the schema's."""
    cur = db.execute("SELECT * FROM steps ORDER BY idx")
    names = [d[0] for d in cur.description]
    return [Step(**dict(zip(names, row, strict=True))) for row in cur.fetchall()]


def select_events(db: sqlite3.Connection) -> list[Event]:
    return [
        (int(s), str(lv), str(t))
        for s, lv, t in db.execute("SELECT stamp_ns, level, text FROM events ORDER BY rowid")
    ]


def read_log(path: str | Path) -> LogData:
    """Read the mission log at ``path`` read-only (SQLite ``mode=ro``). Raises
    MissionLogError, one line naming the file: no such file, not a mission log, a
    steps table of another schema."""
    db = Path(path)
    if not db.is_file():
        raise MissionLogError(f"{db}: no mission log here")
    try:
        con = sqlite3.connect(f"file:{db.resolve()}?mode=ro", uri=True)
    except sqlite3.Error as exc:
        raise MissionLogError(f"{db}: cannot open: {exc}") from None
    try:
        return LogData(select_mission(con), select_steps(con), select_events(con))
    except sqlite3.DatabaseError as exc:
        raise MissionLogError(f"{db}: not a readable mission log: {exc}") from None
    except TypeError as exc:  # a steps table with other columns
        raise MissionLogError(
            f"{db}: steps table does not match the mission log schema: {exc}"
        ) from None
    finally:
        con.close()


def read_run(run_dir: str | Path) -> tuple[Path, LogData, dict[str, Any]]:
    """A run folder's mission log (``RUN_DIR/mission.db``, read-only): its path, its
    data and its mission row. Raises MissionLogError, one line: not a run folder, an
    unreadable log, an empty mission table."""
    run = Path(run_dir)
    db = run / "mission.db"
    if not db.is_file():
        raise MissionLogError(f"{db}: no mission log here (is {run} a run folder?)")
    data = read_log(db)
    if data.mission is None:
        raise MissionLogError(f"{db}: the mission table is empty")
    return db, data, dict(data.mission)
