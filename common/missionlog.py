"""The mission log's schema and its read-only reader: every step of a survey in SQLite,
``runs/<mission>/mission.db``. The mission service writes it (``services/mission/log.py``,
one transaction per change); registration and anything else only read it, through
:func:`read_log`, which opens it with SQLite's ``mode=ro`` so a reader that fails or is
killed can never lose or corrupt it.

:data:`SCHEMA` holds the tables and, after each line of columns, what they mean
(docs/mission-log.md's tables are made from it, ``make docs``). Times are nanoseconds on
the mission service's clock (sim time in simulation); lengths in metres, angles in
radians, in the ``field`` frame.
"""

from __future__ import annotations

import dataclasses
import sqlite3
from pathlib import Path
from typing import Any

SCHEMA = """
CREATE TABLE IF NOT EXISTS mission (
    id TEXT PRIMARY KEY,  -- the mission's name (its folder)
    field TEXT NOT NULL,  -- the field surveyed
    created_ns INTEGER NOT NULL,  -- when the mission was created
    plan_json TEXT NOT NULL,  -- the plan the survey follows, verbatim
    state TEXT NOT NULL  -- `running`, `paused`, `done`, `aborted`
);
CREATE TABLE IF NOT EXISTS steps (
    idx INTEGER PRIMARY KEY,  -- position in the tour, from 0
    scan_id INTEGER NOT NULL,  -- the scan's number (its file `Scan_NNNNN.e57`)
    cand_id INTEGER NOT NULL,  -- the plan's candidate id of the location
    x REAL NOT NULL, y REAL NOT NULL,  -- the planned location
    yaw REAL,  -- the planned heading, NULL when the plan gives none
    status TEXT NOT NULL DEFAULT 'pending',  -- `pending`, `driving`, `scanning`,
    -- `done`, `failed`, `skipped`
    attempts INTEGER NOT NULL DEFAULT 0,  -- scan attempts so far
    file TEXT,  -- the scan file on the scanner's card
    started_ns INTEGER, ended_ns INTEGER,  -- scan start and end
    mean_x REAL, mean_y REAL, mean_z REAL, mean_yaw REAL,  -- the navigation pose's mean
    -- over the scan
    sd_x REAL, sd_y REAL, sd_z REAL, sd_yaw REAL,  -- its standard deviation over the scan
    pitch REAL, roll REAL,  -- the scanner inclinometer's pitch and roll for the scan
    reason TEXT,  -- why a step failed or was skipped
    nav_roll REAL, nav_pitch REAL,  -- the mean tilt (IMU) navigation turned the antennas'
    -- lever arms by over the scan; NULL for a planar estimate (antennas taken upright)
    pose_x REAL, pose_y REAL, pose_z REAL, pose_yaw REAL  -- the navigation pose the scan
    -- is placed with: by default the estimate at the scan's end (`[services.mission]
    -- scan_pose`); NULL in a log written before these columns, whose readers take the means
);
CREATE TABLE IF NOT EXISTS events (
    stamp_ns INTEGER NOT NULL,  -- when
    level TEXT NOT NULL,  -- `info`, `warning`, `error`
    text TEXT NOT NULL  -- one line
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
    """One row of ``steps`` (:data:`SCHEMA` says what each column means)."""

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
