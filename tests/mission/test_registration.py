"""The end-of-mission registration child process: its failure is reported as one
mission event naming the cause, the mission log is left as it was, and the child
reads its options from the manifest the mission service was started with. The
traits follow a registration that succeeded, in a child process of their own."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from common.messages.mission import COMPUTING_TRAITS
from services.mission.registration import TRAITS_MODULE, RegistrationJob


def _run(job: RegistrationJob) -> list[tuple[str, str]]:
    got: list[tuple[str, str]] = []
    ended = threading.Event()

    def report(level: str, text: str) -> None:
        got.append((level, text))
        ended.set()

    job.report = report
    job.start()
    assert ended.wait(60), "the registration child did not end"
    assert not job.running
    return got


def test_a_failing_registration_is_reported_and_touches_no_log(tmp_path: Path) -> None:
    db = tmp_path / "mission.db"
    db.write_bytes(b"not a database" * 64)
    before = db.read_bytes()
    [(level, text)] = _run(RegistrationJob(tmp_path, lambda lv, t: None))
    assert level == "error"
    assert text.startswith("registration failed (exit 2): ") and "mission.db" in text
    assert db.read_bytes() == before
    assert (tmp_path / "register.log").is_file()


def test_the_child_reads_the_manifests_register_section(tmp_path: Path) -> None:
    manifest = tmp_path / "m.toml"
    manifest.write_text('machine = "t"\n[services.register]\nlaz_voxl = 0.02\n')
    job = RegistrationJob(tmp_path, lambda lv, t: None, manifest)
    assert job.command()[-4:] == ["services.register", str(tmp_path), "--manifest", str(manifest)]
    [(level, text)] = _run(job)
    assert level == "error" and "[services.register]" in text and "laz_voxl" in text


def test_stop_ends_a_running_registration_without_a_report(tmp_path: Path) -> None:
    got: list[tuple[str, str]] = []
    job = RegistrationJob(tmp_path, lambda lv, t: got.append((lv, t)))
    job.start()
    job.stop(timeout=5.0)
    assert not job.running and got == []


def test_traits_follow_a_registration_that_succeeded_and_their_failure_is_reported(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # a registration that succeeds without scans: a module of our own on the path
    (tmp_path / "lib").mkdir()
    (tmp_path / "lib" / "fake_register.py").write_text("print('registered')\n")
    monkeypatch.setenv("PYTHONPATH", str(tmp_path / "lib"))
    run = tmp_path / "run"
    run.mkdir()
    got: list[tuple[str, str]] = []
    ended = threading.Event()

    def report(level: str, text: str) -> None:
        got.append((level, text))
        if text.startswith("traits "):
            ended.set()

    job = RegistrationJob(run, report, traits=True, modules=("fake_register", TRAITS_MODULE))
    job.start()
    assert ended.wait(60), got
    assert [lv for lv, _ in got] == ["info", "info", "error"]
    assert got[0][1].startswith("registration done") and got[1][1] == COMPUTING_TRAITS
    assert got[2][1].startswith("traits failed (exit 2): ") and "mission.db" in got[2][1]
    assert (run / "traits.log").is_file()
