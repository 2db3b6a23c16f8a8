"""The mission log's writer: every step of a survey in SQLite (``runs/<mission>/mission.db``),
one transaction per change, written before the next step begins, so a crash or a
power cut loses nothing and a restart resumes at the first unfinished scan.

The schema, the :class:`~common.missionlog.Step` row and the read-only reader that
everyone else uses are in :mod:`common.missionlog` (also described in the README).
"""

from __future__ import annotations

import dataclasses
import sqlite3
import threading
from pathlib import Path
from typing import Any

from common.missionlog import (
    ADDED_COLUMNS,
    FINISHED,
    SCHEMA,
    STEP_STATES,
    Event,
    Step,
    select_events,
    select_mission,
    select_steps,
)


class MissionLog:
    """One mission's database. Every method commits before it returns."""

    def __init__(self, path: Path) -> None:
        self.path = path
        path.parent.mkdir(parents=True, exist_ok=True)
        self.db = sqlite3.connect(path, check_same_thread=False, isolation_level=None)
        # one connection, used by the survey's worker and the command handler (a pause
        # written while a step is updated): sqlite3 does not serialise them itself
        self._lock = threading.RLock()
        self.db.execute("PRAGMA journal_mode=WAL")
        self.db.execute("PRAGMA synchronous=FULL")  # a power cut must not lose a step
        self.db.executescript(SCHEMA)
        have = {r[1] for r in self.db.execute("PRAGMA table_info(steps)")}
        for name, typ in ADDED_COLUMNS:
            if name not in have:  # a log written before the column existed
                self.db.execute(f"ALTER TABLE steps ADD COLUMN {name} {typ}")

    def close(self) -> None:
        self.db.close()

    def _tx(self, sql: str, args: tuple[Any, ...] = ()) -> None:
        with self._lock, self.db:  # one transaction
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
        with self._lock, self.db:
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
        with self._lock:
            return select_mission(self.db)

    def set_state(self, state: str) -> None:
        self._tx("UPDATE mission SET state = ?", (state,))

    def steps(self) -> list[Step]:
        with self._lock:
            return select_steps(self.db)

    def counts(self) -> tuple[int, int, int]:
        """(done, failed or skipped, all) of the steps."""
        steps = self.steps()
        done = sum(s.status == "done" for s in steps)
        return done, sum(s.status in ("failed", "skipped") for s in steps), len(steps)

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

    def events(self) -> list[Event]:
        with self._lock:
            return select_events(self.db)
