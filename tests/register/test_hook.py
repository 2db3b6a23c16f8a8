"""The end-of-mission registration child process: its failure is reported as one
mission event naming the cause, and the mission log is left as it was."""

from __future__ import annotations

import threading
from pathlib import Path

from services.register.hook import RegistrationJob


def test_a_failing_registration_is_reported_and_touches_no_log(tmp_path: Path) -> None:
    db = tmp_path / "mission.db"
    db.write_bytes(b"not a database" * 64)
    before = db.read_bytes()
    got: list[tuple[str, str]] = []
    ended = threading.Event()

    def report(level: str, text: str) -> None:
        got.append((level, text))
        ended.set()

    job = RegistrationJob(tmp_path, report)
    job.start()
    assert ended.wait(60), "the registration child did not end"
    assert not job.running
    [(level, text)] = got
    assert level == "error"
    assert text.startswith("registration failed (exit 2): ") and "mission.db" in text
    assert db.read_bytes() == before
    assert (tmp_path / "register.log").is_file()


def test_stop_ends_a_running_registration_without_a_report(tmp_path: Path) -> None:
    got: list[tuple[str, str]] = []
    job = RegistrationJob(tmp_path, lambda lv, t: got.append((lv, t)))
    job.start()
    job.stop(timeout=5.0)
    assert not job.running and got == []
