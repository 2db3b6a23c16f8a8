"""The one schema of every benchmark's JSON (``docs/bench/<name>.json``): its figures,
each with its target, verdict and what would close a miss, the experiments that
failed, and the reader and writer of the files."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any, Literal

import msgspec

from common.files import write_atomic

SCHEMA = "phenorover.bench/1"
Verdict = Literal["met", "missed", "no target"]
Op = Literal["<=", ">="]


class ResultError(ValueError):
    """A results file that is missing, unreadable or not of this schema (one line)."""


class Target(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The figure must be ``op value``, in the figure's unit."""

    op: Op
    value: float

    def met(self, v: float) -> bool:
        return v <= self.value if self.op == "<=" else v >= self.value


@dataclasses.dataclass(frozen=True)
class Goal:
    """A target as a benchmark sets it, with what would close it if missed: stated with
    the target, so that a miss is never reported without it. Raises ValueError on an
    unknown ``op``, a non-finite ``value`` or an empty ``close``."""

    op: Op
    value: float
    close: str

    def __post_init__(self) -> None:
        if self.op not in ("<=", ">="):
            raise ValueError(f"Goal.op: {self.op!r} is not '<=' or '>='")
        if not math.isfinite(self.value):
            raise ValueError(f"Goal.value: {self.value!r} is not finite")
        if not self.close.strip():
            raise ValueError("Goal.close: say what would close the target if it is missed")


class Figure(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """One measured figure. ``value`` is None when it could not be measured
    (``what_would_close_it`` then says why); ``headline``: the figure that answers the
    target in simulation (the true one); ``paper``: the paper's figure in the same unit,
    for comparison; ``error_models``: model name -> its parameters, as in force."""

    name: str
    value: float | None
    unit: str
    target: Target | None
    verdict: Verdict
    what_would_close_it: str
    error_models: dict[str, str]
    date: str
    commit: str
    machine: str
    headline: bool = False
    paper: float | None = None
    note: str = ""


class Failure(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """An experiment that did not produce its figures, and why."""

    experiment: str
    reason: str


class BenchResult(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """A benchmark's results file. ``exit_code``: what the benchmark exited with (non-zero
    when an experiment failed); ``details``: the benchmark's raw numbers, free-form."""

    schema: str
    benchmark: str
    started: str
    finished: str
    commit: str
    machine: str
    exit_code: int
    failures: list[Failure]
    figures: list[Figure]
    details: dict[str, Any] = {}


def verdict(value: float | None, target: Target | None) -> Verdict:
    """``no target`` without one; ``missed`` when not met or not measured."""
    if target is None:
        return "no target"
    return "met" if value is not None and target.met(value) else "missed"


def write(res: BenchResult, path: Path) -> None:
    """Write ``res`` to ``path`` atomically (a reader never sees half a file)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, msgspec.json.format(msgspec.json.encode(res), indent=1) + b"\n")


def load(path: Path) -> BenchResult:
    """Read a results file. Raises ResultError (one line) when it is missing,
    unreadable or not of this schema."""
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ResultError(f"{path} is missing") from None
    except OSError as exc:
        raise ResultError(f"{path}: {exc.strerror}") from None
    try:
        head = msgspec.json.decode(raw)
    except msgspec.DecodeError as exc:
        raise ResultError(f"{path}: not JSON ({exc})") from None
    if not isinstance(head, dict) or head.get("schema") != SCHEMA:
        found = head.get("schema") if isinstance(head, dict) else None
        raise ResultError(f"{path}: not a {SCHEMA} result (schema {found!r}): an older format")
    try:
        return msgspec.json.decode(raw, type=BenchResult)
    except msgspec.ValidationError as exc:
        raise ResultError(f"{path}: {exc}") from None
