"""The systemd units in deploy/systemd start a machine's deployment at boot and bring it
back after a crash of the launcher: each runs ``phenorover up`` on a shipped manifest,
restarts it without ever giving up, stops it through the launcher's own SIGTERM path
within a bounded time, and runs as a service user whose run folder is its own.

The units are read with a small parser of systemd's syntax (sections, ``Key=Value``,
repeated keys); where ``systemd-analyze`` is installed each unit is also verified by
systemd itself. Every check is also run on a broken copy of the unit, so none of them
passes vacuously."""

from __future__ import annotations

import inspect
import re
import shlex
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from common.config import load_manifest
from phenorover.launcher import Launcher
from tests.conftest import REPO

UNIT_DIR = REPO / "deploy" / "systemd"
UNITS = sorted(UNIT_DIR.glob("*.service"))
MANIFESTS = {p.stem: p for p in (REPO / "deploy").glob("*.toml")}
# the machines of the shipped hardware manifests: each must be started by a unit
HARDWARE = ("robot", "jetson", "basestation")
# the launcher's stop(): SIGTERM to every service, SIGKILL after this many seconds
GRACE_S: float = inspect.signature(Launcher).parameters["grace_s"].default

Unit = dict[str, dict[str, list[str]]]


def parse_unit(text: str) -> Unit:
    """A unit file as {section: {key: [values in order]}}: keys may repeat (an empty
    value resets the list, as systemd does), ``#``/``;`` start comment lines, and a
    trailing backslash continues a line."""
    unit: Unit = {}
    section: dict[str, list[str]] | None = None
    pending = ""
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = pending + raw.strip()
        pending = ""
        if not line or line[0] in "#;":
            continue
        if line.endswith("\\"):
            pending = line[:-1].rstrip() + " "
            continue
        if line.startswith("[") and line.endswith("]"):
            section = unit.setdefault(line[1:-1], {})
            continue
        key, sep, value = line.partition("=")
        if section is None or not sep:
            raise ValueError(f"line {lineno}: not a [section] or Key=Value: {raw!r}")
        values = section.setdefault(key.strip(), [])
        if value.strip():
            values.append(value.strip())
        else:
            values.clear()
    return unit


def get(unit: Unit, section: str, key: str) -> list[str]:
    return unit.get(section, {}).get(key, [])


def last(unit: Unit, section: str, key: str, default: str = "") -> str:
    values = get(unit, section, key)
    return values[-1] if values else default


def words(unit: Unit, section: str, key: str) -> list[str]:
    """A list-valued setting (After=, WantedBy=, ...): every value's words."""
    return [w for v in get(unit, section, key) for w in v.split()]


_SPAN_UNITS = {
    "us": 1e-6, "usec": 1e-6, "ms": 1e-3, "msec": 1e-3,
    "s": 1.0, "sec": 1.0, "second": 1.0, "seconds": 1.0, "": 1.0,
    "m": 60.0, "min": 60.0, "minute": 60.0, "minutes": 60.0,
    "h": 3600.0, "hr": 3600.0, "hour": 3600.0, "hours": 3600.0,
}  # fmt: skip


def seconds(span: str) -> float:
    """A systemd time span ("20", "20s", "1min 30s", "500ms", "infinity") in seconds."""
    if span.strip() == "infinity":
        return float("inf")
    parts = re.findall(r"(\d+(?:\.\d+)?)\s*([a-z]*)", span)
    if not parts or "".join(n + u for n, u in parts) != span.replace(" ", ""):
        raise ValueError(f"not a time span: {span!r}")
    return sum(float(n) * _SPAN_UNITS[u] for n, u in parts)


def instances(unit_path: Path) -> list[str]:
    """The instances a unit is checked as: a template (name@.service) as each hardware
    machine, a plain unit as itself (instance "")."""
    return list(HARDWARE) if unit_path.name.endswith("@.service") else [""]


def expand(value: str, instance: str) -> str:
    return value.replace("%i", instance).replace("%I", instance)


def exec_argv(value: str) -> list[str]:
    """An Exec*= command line without systemd's prefixes (@ - : + !)."""
    argv = shlex.split(value)
    argv[0] = argv[0].lstrip("@-:+!")
    return argv


def manifest_of(unit: Unit, instance: str) -> Path:
    """The manifest the unit's ExecStart runs ``phenorover up`` on."""
    return Path(expand(exec_argv(last(unit, "Service", "ExecStart"))[-1], instance))


def problems(unit: Unit, instance: str) -> list[str]:
    """Everything wrong with a unit run as ``instance``, a line each (none: it will do)."""
    out: list[str] = []
    service = "Service"

    # ExecStart: phenorover up on a shipped manifest, by absolute paths
    starts = get(unit, service, "ExecStart")
    if len(starts) != 1:
        return [f"ExecStart: want exactly one command, got {starts}"]
    argv = [expand(a, instance) for a in exec_argv(starts[0])]
    if Path(argv[0]).name != "phenorover" or argv[1:2] != ["up"] or len(argv) != 3:
        out.append(f"ExecStart: want `phenorover up MANIFEST`, got {argv}")
    if not Path(argv[0]).is_absolute():
        out.append(f"ExecStart: {argv[0]} is not an absolute path")
    manifest = Path(argv[-1])
    if not manifest.is_absolute() or manifest.suffix != ".toml":
        out.append(f"ExecStart: manifest {manifest}: want an absolute path to a .toml")
    if manifest.stem not in MANIFESTS:
        out.append(f"ExecStart: manifest {manifest}: no deploy/{manifest.stem}.toml ships")
    # a pre-check that fails (a device not there yet at boot) would keep the whole
    # machine down, router included, restarting; `up` itself refuses a bad manifest
    for pre in get(unit, service, "ExecStartPre"):
        if "--check" in exec_argv(pre):
            out.append(f"ExecStartPre: {pre}: `up --check` belongs to installation")

    # restarted after a crash, never given up on
    if last(unit, service, "Restart", "no") not in ("on-failure", "always"):
        out.append(f"Restart: {last(unit, service, 'Restart', 'no')}: want on-failure")
    restart_s = seconds(last(unit, service, "RestartSec", "100ms"))
    interval_s = seconds(last(unit, "Unit", "StartLimitIntervalSec", "10s"))
    burst = int(last(unit, "Unit", "StartLimitBurst", "5"))
    # starts come at least RestartSec apart: at most interval/RestartSec + 1 in any window
    if interval_s > 0 and interval_s / restart_s + 1 > burst:
        out.append(
            f"StartLimitIntervalSec {interval_s:g} s, StartLimitBurst {burst}, RestartSec "
            f"{restart_s:g} s: systemd would give up on a launcher that keeps crashing"
        )

    # stopped through the launcher: SIGTERM to it alone, and time for its grace
    signal = last(unit, service, "KillSignal", "SIGTERM")
    if signal not in ("SIGTERM", "TERM", "15"):
        out.append(f"KillSignal: {signal}: the launcher stops its services on SIGTERM")
    if last(unit, service, "KillMode", "control-group") != "mixed":
        out.append(
            "KillMode: want mixed (SIGTERM to the launcher alone: it stops its services; "
            "one that exits before the launcher has begun stopping looks like a crash)"
        )
    timeout_s = seconds(last(unit, service, "TimeoutStopSec", "infinity"))
    if not GRACE_S < timeout_s < float("inf"):
        out.append(f"TimeoutStopSec: {timeout_s:g} s: want bounded and over {GRACE_S:g} s")

    # started once the network is up, at boot
    for key in ("After", "Wants"):
        if "network-online.target" not in words(unit, "Unit", key):
            out.append(f"{key}: want network-online.target")
    if "multi-user.target" not in words(unit, "Install", "WantedBy"):
        out.append("[Install] WantedBy: want multi-user.target")

    # a service user with its own state folder, where the run folder lands
    if last(unit, service, "User", "root") in ("root", "0"):
        out.append("User: want a dedicated service user, not root")
    env: dict[str, str] = {}
    for assignments in get(unit, service, "Environment"):
        for item in shlex.split(assignments):
            key, _, value = item.partition("=")
            env[key] = value
    if env.get("PYTHONUNBUFFERED") != "1":
        out.append("Environment: want PYTHONUNBUFFERED=1 (stdout is the journal, not a tty)")
    state = [f"/var/lib/{d}" for d in words(unit, service, "StateDirectory")]
    cache = [f"/var/cache/{d}" for d in words(unit, service, "CacheDirectory")]
    workdir = last(unit, service, "WorkingDirectory")

    def writable(path: str) -> bool:
        return any(path == d or path.startswith(d + "/") for d in state + cache)

    if not writable(workdir):
        out.append(f"WorkingDirectory {workdir!r}: not under a StateDirectory {state}")
    if manifest.stem in MANIFESTS:
        run_dir = load_manifest(MANIFESTS[manifest.stem]).run_dir
        where = run_dir if Path(run_dir).is_absolute() else f"{workdir}/{run_dir}"
        if not writable(where):
            out.append(f"run_dir {run_dir} ({where}): not in the unit's state folder {state}")
    # numba caches compiled kernels next to their source, root's, or in a home the
    # service user may not have: without a folder of its own the planner cannot start
    if not writable(env.get("NUMBA_CACHE_DIR", "")):
        out.append("Environment: NUMBA_CACHE_DIR: want a folder under a Cache/StateDirectory")
    return out


def cases() -> list[tuple[Path, str]]:
    return [(p, i) for p in UNITS for i in instances(p)]


def case_id(case: tuple[Path, str]) -> str:
    return f"{case[0].name}:{case[1]}" if case[1] else case[0].name


def test_there_are_units() -> None:
    assert UNITS, f"no *.service in {UNIT_DIR}"


def test_every_hardware_machine_is_started_by_a_unit() -> None:
    started = {manifest_of(parse_unit(p.read_text()), i).stem for p, i in cases()}
    assert set(HARDWARE) <= started, f"no unit runs {sorted(set(HARDWARE) - started)}"
    assert set(HARDWARE) <= set(MANIFESTS)


@pytest.mark.parametrize("case", cases(), ids=case_id)
def test_unit(case: tuple[Path, str]) -> None:
    path, instance = case
    found = problems(parse_unit(path.read_text()), instance)
    assert not found, "\n".join([f"{path} as {instance or path.stem}:", *found])


# Broken copies of a unit, each of which the checks above must refuse.
Mutation = Callable[[Unit], None]
BIN = "/opt/phenorover/venv/bin/phenorover"


def _set(section: str, key: str, *values: str) -> Mutation:
    def mutate(unit: Unit) -> None:
        unit.setdefault(section, {})[key] = list(values)

    return mutate


def _drop(section: str, key: str) -> Mutation:
    def mutate(unit: Unit) -> None:
        unit.get(section, {}).pop(key, None)

    return mutate


# name -> (the break, what the problem line must say)
MUTATIONS: dict[str, tuple[Mutation, str]] = {
    "no network-online After": (_set("Unit", "After", "network.target"), "After:"),
    "no network-online Wants": (_drop("Unit", "Wants"), "Wants:"),
    "never restarted": (_set("Service", "Restart", "no"), "Restart:"),
    "gives up restarting": (_set("Unit", "StartLimitIntervalSec", "60s"), "give up"),
    "SIGKILL to stop": (_set("Service", "KillSignal", "SIGKILL"), "KillSignal:"),
    "SIGTERM to every process": (_set("Service", "KillMode", "control-group"), "KillMode:"),
    "stop shorter than the grace": (_set("Service", "TimeoutStopSec", "3s"), "TimeoutStopSec:"),
    "stop unbounded": (_drop("Service", "TimeoutStopSec"), "TimeoutStopSec:"),
    "not a shipped manifest": (
        _set("Service", "ExecStart", f"{BIN} up /etc/phenorover/rover.toml"),
        "no deploy/rover.toml",
    ),
    "not up": (_set("Service", "ExecStart", f"{BIN} status /etc/x/robot.toml"), "phenorover up"),
    "check before start": (
        _set("Service", "ExecStartPre", f"{BIN} up --check /etc/x.toml"),
        "ExecStartPre:",
    ),
    "not at boot": (_set("Install", "WantedBy", "graphical.target"), "WantedBy:"),
    "as root": (_drop("Service", "User"), "User:"),
    "buffered stdout": (
        _set("Service", "Environment", "NUMBA_CACHE_DIR=/var/cache/phenorover"),
        "PYTHONUNBUFFERED",
    ),
    "run folder elsewhere": (_set("Service", "StateDirectory", "elsewhere"), "StateDirectory"),
    "no numba cache": (_set("Service", "Environment", "PYTHONUNBUFFERED=1"), "NUMBA_CACHE_DIR"),
}


@pytest.mark.parametrize("name", sorted(MUTATIONS))
def test_a_broken_unit_is_refused(name: str) -> None:
    assert UNITS
    path, instance = cases()[0]
    unit = parse_unit(path.read_text())
    mutate, expected = MUTATIONS[name]
    mutate(unit)
    found = problems(unit, instance)
    assert any(expected in line for line in found), f"{name}: want {expected!r}, got {found}"


def test_parser() -> None:
    unit = parse_unit(
        "# comment\n[Unit]\nAfter=a.target\nAfter=b.target c.target\n; also a comment\n"
        "[Service]\nExecStart=/bin/x \\\n  --flag\nEnvironment=A=1\nEnvironment=\n"
        "Environment=B=2 'C=3 4'\n"
    )
    assert words(unit, "Unit", "After") == ["a.target", "b.target", "c.target"]
    assert get(unit, "Service", "ExecStart") == ["/bin/x --flag"]
    assert get(unit, "Service", "Environment") == ["B=2 'C=3 4'"]
    assert seconds("1min 30s") == 90.0 and seconds("20") == 20.0 and seconds("500ms") == 0.5
    with pytest.raises(ValueError):
        parse_unit("Key=value\n")


# --- systemd's own verdict --------------------------------------------------------

SYSTEMD_ANALYZE = shutil.which("systemd-analyze")
needs_systemd = pytest.mark.skipif(
    SYSTEMD_ANALYZE is None, reason="systemd-analyze is not installed (apt-get install systemd)"
)


def verify(text: str, name: str, folder: Path) -> list[str]:
    """``systemd-analyze verify`` on a unit, with its ExecStart binary replaced by one
    that exists here (verify refuses a missing one): the lines that concern the unit.
    Verify exits 0 after a mere warning (an unknown key, a bad value "ignoring"), so a
    line naming the unit is a problem too."""
    binary = exec_argv(parse_unit(text)["Service"]["ExecStart"][-1])[0]
    path = folder / name
    path.write_text(text.replace(binary, sys.executable))
    assert SYSTEMD_ANALYZE is not None
    r = subprocess.run(
        [SYSTEMD_ANALYZE, "verify", "--man=no", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    stem = name.partition("@")[0].removesuffix(".service")
    lines = [ln for ln in (r.stdout + r.stderr).splitlines() if stem in ln]
    if r.returncode != 0:
        lines.append(f"exit status {r.returncode}: {(r.stdout + r.stderr).strip()[-500:]}")
    return lines


@needs_systemd
@pytest.mark.parametrize("path", UNITS, ids=lambda p: p.name)
def test_systemd_verifies_the_unit(path: Path, tmp_path: Path) -> None:
    found = verify(path.read_text(), path.name, tmp_path)
    assert not found, "\n".join([f"systemd-analyze verify {path}:", *found])


@needs_systemd
def test_systemd_verify_catches_a_bad_unit(tmp_path: Path) -> None:
    assert UNITS
    text = UNITS[0].read_text().replace("Restart=on-failure", "Restart=sometimes")
    assert "Restart=sometimes" in text
    assert verify(text, UNITS[0].name, tmp_path) != []
