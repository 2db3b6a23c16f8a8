"""The same seed gives the same survey whatever the pace and the load: the tiny field
surveyed by ``phenorover sim`` in lockstep three times (as fast as it goes on a quiet
machine, then, at the same time, as fast as it goes beside a busy loop on both cores
and capped at a real-time factor) leaves identical mission logs: every step's
status, times and scan pose to the last bit, and every event of the survey."""

from __future__ import annotations

import re
import subprocess
import sys
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from common.missionlog import read_log
from phenorover.cpu import read_use
from tests.conftest import REPO, free_port

TINY = REPO / "tests" / "data" / "tiny.toml"
FILES = re.compile(r"summary: .*; files in (\S+)")


def manifest(tmp: Path, name: str, rtf: float) -> Path:
    """A deployment of its own (``name``: its run folder and scanner card) at ``rtf``."""
    tmp = tmp / name
    tmp.mkdir()
    path = tmp / "lockstep.toml"
    path.write_text(f"""
machine = "sim"
clock = "sim"
lockstep = true
lockstep_deadline_s = 30.0
field = "{TINY}"
run_dir = "{tmp / "runs"}"
[zenoh]
listen = ["tcp/127.0.0.1:{free_port()}"]
[services.sim]
real_time_factor = {rtf}
clock_hz = 20.0
seed = 3
resume = false
[services.gnss]
backend = "sim"
[services.base]
backend = "sim"
rate_hz = 20.0
[services.scanner]
backend = "sim"
storage_dir = "{tmp / "card"}"
sim_scan_time_s = 5.0
render_step_deg = 2.0
[services.nav]
[services.planner]
[services.mission]
register_on_done = false
""")
    return path


def survey(path: Path) -> Path:
    """``phenorover sim`` on ``path``: the survey's run folder."""
    r = subprocess.run(
        [sys.executable, "-m", "phenorover", "sim", "--manifest", str(path)],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=600,
    )
    found = FILES.search(r.stdout)
    assert r.returncode == 0 and found, r.stdout[-3000:] + r.stderr[-3000:]
    return Path(found.group(1))


def what_happened(run: Path) -> tuple[list[Any], list[Any]]:
    """The survey's steps (all their columns) and its events up to its end, the
    mission's name (a wall-clock date) and its deployment's folder taken out."""
    log = read_log(run / "mission.db")
    assert log.mission is not None
    name, folder = log.mission["id"], str(run.parent.parent)

    def same(v: Any) -> Any:
        return v.replace(name, "M").replace(folder, "D") if isinstance(v, str) else v

    steps = [tuple(same(v) for v in vars(s).values()) for s in log.steps]
    events = []
    for stamp, level, text in log.events:
        events.append((stamp, level, same(text)))
        if text == f"mission {name} done":
            break
    return steps, events


def first_difference(a: tuple[list[Any], list[Any]], b: tuple[list[Any], list[Any]]) -> str:
    """Where two surveys part (their first differing step or event), for the failure
    message: pytest's own shows only that two long lists differ."""
    for what, xs, ys in (("step", a[0], b[0]), ("event", a[1], b[1])):
        for i, (x, y) in enumerate(zip(xs, ys, strict=False)):
            if x != y:
                return f"{what} {i}:\n  first: {x}\n  other: {y}"
        if len(xs) != len(ys):
            return f"{len(xs)} {what}s against {len(ys)}"
    return "the same"


@contextmanager
def busy_cores(n: int = 2) -> Iterator[None]:
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait()


def test_the_same_seed_gives_the_same_survey_at_any_pace_and_under_load(tmp_path: Path) -> None:
    first = survey(manifest(tmp_path, "fast", 1000.0))
    fast = what_happened(first)
    steps, events = fast
    # what each service cost over the survey, from the launcher's reading of /proc
    use = read_use(first / "cpu.json")
    assert use is not None and use.sim_s > 0
    assert set(use.cpu_s) == {"sim", "base", "gnss", "scanner", "nav", "planner", "mission"}
    assert all(c > 0 for c in use.cpu_s.values()), use
    assert len(steps) == 3 and all(s[6] == "done" for s in steps), steps
    assert events[-1][2] == "mission M done"
    # every service's configuration, the mission's own too (asked mid-step)
    saved = (first / "config.toml").read_text()
    assert all(f"[services.{n}]" in saved for n in use.cpu_s), saved
    # the loaded survey and the paced one side by side: each is load for the other too
    with busy_cores(), ThreadPoolExecutor(2) as pool:
        runs = [
            pool.submit(survey, manifest(tmp_path, name, rtf))
            for name, rtf in (("loaded", 1000.0), ("paced", 4.0))
        ]
        loaded, paced = (what_happened(r.result()) for r in runs)
    assert loaded == fast, first_difference(fast, loaded)
    assert paced == fast, first_difference(fast, paced)
