"""The CPU a service used, as the launcher reads it from /proc."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from phenorover.cpu import CpuUse, Mark, cpu_seconds, parse_stat, read_use

# /proc/PID/stat of a process named "a) b" (a name may hold both): utime 250, stime 50,
# cutime 100, cstime 0 clock ticks
STAT = "1234 (a) b) S 1 1234 1234 0 -1 4194304 100 0 0 0 250 50 100 0 20 0 1 0 5 0 0\n"


def test_stat_fields_are_counted_from_the_last_parenthesis() -> None:
    assert parse_stat(STAT) == pytest.approx(400 / os.sysconf("SC_CLK_TCK"))


@pytest.mark.parametrize("text", ["", "garbage", "1 (x) S 1 2", "1 (x) S " + "z " * 20])
def test_what_is_not_a_stat_gives_nothing(text: str) -> None:
    assert parse_stat(text) is None


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="Linux only")
def test_a_process_that_worked_shows_its_cpu_and_a_gone_one_none() -> None:
    busy = "import time\nt = time.process_time()\nwhile time.process_time() - t < 0.3: pass"
    proc = subprocess.Popen(
        [sys.executable, "-c", busy + "\nimport sys; sys.stdin.read()"], stdin=subprocess.PIPE
    )
    try:
        deadline = time.monotonic() + 60
        used = 0.0
        while used < 0.3 and time.monotonic() < deadline:
            used = cpu_seconds(proc.pid) or 0.0
        assert used >= 0.3
    finally:
        proc.kill()
        proc.wait()
    assert cpu_seconds(proc.pid) is None


def test_use_between_two_marks_per_simulated_second(tmp_path: Path) -> None:
    a = Mark(wall_s=10.0, sim_s=0.0, cpu_s={"sim": 1.0, "nav": 0.5})
    b = Mark(wall_s=30.0, sim_s=200.0, cpu_s={"sim": 41.0, "nav": 10.5, "viz": 4.0})
    use = CpuUse.between(a, b)
    assert use.per_sim_s() == pytest.approx({"sim": 0.2, "nav": 0.05, "viz": 0.02})
    line = use.line()
    assert line.index("sim 0.200") < line.index("nav 0.050") < line.index("viz 0.020")
    assert "200 s simulated in 20 s" in line
    use.write(tmp_path / "cpu.json")
    assert read_use(tmp_path / "cpu.json") == use


def test_no_simulated_time_is_said_and_a_bad_file_is_none(tmp_path: Path) -> None:
    still = CpuUse(0.0, 5.0, {"sim": 1.0})
    assert still.per_sim_s() == {}
    assert "no simulated time" in still.line()
    (tmp_path / "cpu.json").write_text("{not json")
    assert read_use(tmp_path / "cpu.json") is None
    assert read_use(tmp_path / "missing.json") is None
