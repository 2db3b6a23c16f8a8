"""The mission log: every step of a survey in SQLite (``runs/<mission>/mission.db``),
one transaction per change, written before the next step begins, so a crash or a
power cut loses nothing and a restart resumes at the first unfinished scan.

Schema (also in the README):

- ``mission``: one row: ``id``, ``field``, ``created_ns``, ``plan_json`` (the plan
  the survey follows, verbatim), ``state`` (running, paused, done, aborted).
- ``steps``: one row per scan location in tour order: ``idx``, ``scan_id``,
  ``cand_id``, planned ``x``, ``y``, ``yaw``; ``status`` (pending, driving, scanning,
  done, failed, skipped); ``attempts``; ``file`` (the scan on the scanner's card);
  ``started_ns``/``ended_ns`` (scan start and end, clock of the mission service);
  pose statistics over the scan from the navigation estimate: ``mean_x``,
  ``mean_y``, ``mean_z``, ``mean_yaw``, ``sd_x``, ``sd_y``, ``sd_z``, ``sd_yaw``
  (metres, radians); the inclinometer's ``pitch`` and ``roll`` (radians); ``reason``
  for a failed or skipped step.
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
    sd_x REAL, sd_y REAL, sd_z REAL, sd_yaw REAL, pitch REAL, roll REAL, reason TEXT
);
CREATE TABLE IF NOT EXISTS events (
    stamp_ns INTEGER NOT NULL, level TEXT NOT NULL, text TEXT NOT NULL
);
"""

STEP_STATES = ("pending", "driving", "scanning", "done", "failed", "skipped")
FINISHED = ("done", "failed", "skipped")


@dataclasses.dataclass(frozen=True)
class Step:
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


class MissionLog:
    """One mission's database. Every method commits before it returns."""

    def __init__(self, path: Path) -> None:
        self.path = path
        path.parent.mkdir(parents=True, exist_ok=True)
        self.db = sqlite3.connect(path, check_same_thread=False, isolation_level=None)
        self.db.execute("PRAGMA journal_mode=WAL")
        self.db.execute("PRAGMA synchronous=FULL")  # a power cut must not lose a step
        self.db.executescript(SCHEMA)

    def close(self) -> None:
        self.db.close()

    def _tx(self, sql: str, args: tuple[Any, ...] = ()) -> None:
        with self.db:  # one transaction
            self.db.execute("BEGIN")
            self.db.execute(sql, args)

    def create(
        self,
        mission: str,
        field: str,
        created_ns: int,
        plan_json: str,
        steps: list[tuple[int, int, float, float, float | None]],
    ) -> None:
        """Write the mission and its steps (scan_id, cand_id, x, y, yaw) at once."""
        with self.db:
            self.db.execute("BEGIN")
            self.db.execute(
                "INSERT INTO mission VALUES (?, ?, ?, ?, 'running')",
                (mission, field, created_ns, plan_json),
            )
            self.db.executemany(
                "INSERT INTO steps (idx, scan_id, cand_id, x, y, yaw) VALUES (?, ?, ?, ?, ?, ?)",
                [(i, *s) for i, s in enumerate(steps)],
            )

    def mission(self) -> dict[str, Any] | None:
        row = self.db.execute(
            "SELECT id, field, created_ns, plan_json, state FROM mission"
        ).fetchone()
        if row is None:
            return None
        return dict(zip(("id", "field", "created_ns", "plan_json", "state"), row, strict=True))

    def set_state(self, state: str) -> None:
        self._tx("UPDATE mission SET state = ?", (state,))

    def steps(self) -> list[Step]:
        cur = self.db.execute("SELECT * FROM steps ORDER BY idx")
        names = [d[0] for d in cur.description]
        return [Step(**dict(zip(names, row, strict=True))) for row in cur.fetchall()]

    def next_step(self) -> Step | None:
        """The first step not finished (done, failed or skipped), in tour order."""
        return next((s for s in self.steps() if s.status not in FINISHED), None)

    def update(self, idx: int, **fields: Any) -> None:
        bad = set(fields) - {f.name for f in dataclasses.fields(Step)} | ({"idx"} & set(fields))
        if bad:
            raise ValueError(f"steps has no updatable column {sorted(bad)}")
        if "status" in fields and fields["status"] not in STEP_STATES:
            raise ValueError(f"step status {fields['status']!r} is not one of {STEP_STATES}")
        cols = ", ".join(f"{k} = ?" for k in fields)
        self._tx(f"UPDATE steps SET {cols} WHERE idx = ?", (*fields.values(), idx))

    def event(self, stamp_ns: int, level: str, text: str) -> None:
        self._tx("INSERT INTO events VALUES (?, ?, ?)", (stamp_ns, level, text))

    def events(self) -> list[tuple[int, str, str]]:
        return list(self.db.execute("SELECT stamp_ns, level, text FROM events ORDER BY rowid"))
