"""Benchmark results: the recorder every benchmark uses, writing the one schema of
their JSON (``docs/bench/<name>.json``, :mod:`.bench_schema`).

A benchmark makes a :class:`Bench`, records every figure with :meth:`Bench.figure`
(value, unit, its :class:`Goal` if it has one, the error models in force), every
experiment that failed with :meth:`Bench.fail`, and ends with :meth:`Bench.finish`:
it prints the figures with their error models, writes the JSON and returns the exit
status, non-zero when an experiment failed. A missed target is not a failure (figures
are reported, never asserted): it is written as missed, with the measured figure and
what would close it. A figure that could not be measured has no value (never a
stand-in number) and says why.

Every figure carries its own date, commit and machine, so one copied out of the file
still says where it came from. Values are in the figure's ``unit``; dates are UTC,
ISO 8601.
"""

from __future__ import annotations

import datetime
import math
import os
import platform
import statistics
import subprocess
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, TextIO

from phenorover.eval.bench_schema import (
    SCHEMA,
    BenchResult,
    Failure,
    Figure,
    Goal,
    ResultError,
    Target,
    load,
    verdict,
    write,
)

REPO = Path(__file__).resolve().parents[1]
#: Where the benchmarks' JSON lives: committed beside the pages rendered from it, so a
#: page re-rendered after one benchmark keeps every other benchmark's figures
BENCH_DIR = Path(__file__).resolve().parents[2] / "docs" / "bench"


def now() -> str:
    return datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")


#: What the benchmarks write, relative to the checkout's top: a change there is their
#: output (an earlier benchmark of the same sitting), not a change to the code that ran
OUTPUTS = ("docs/bench", "docs/results.md", "docs/faults.md", "docs/soak.md")


def git_commit(repo: Path = REPO) -> str:
    """The checkout's short commit, ``+dirty`` when tracked files other than the
    benchmarks' own outputs (:data:`OUTPUTS`) differ from it (then the commit alone
    does not name the code that ran); ``unknown`` without git."""

    def git(*args: str) -> str | None:
        try:
            r = subprocess.run(
                ["git", "--no-optional-locks", *args],
                cwd=repo,
                capture_output=True,
                text=True,
                timeout=30,
            )
        except (OSError, subprocess.TimeoutExpired):
            return None
        return r.stdout.strip() if r.returncode == 0 else None

    head = git("rev-parse", "--short", "HEAD")
    if not head:
        return "unknown"
    outputs = [f":(top,exclude){p}" for p in OUTPUTS]
    dirty = git("status", "--porcelain", "--untracked-files=no", "--", ":(top)", *outputs)
    return f"{head}+dirty" if dirty else head


def machine() -> str:
    """Host, CPU, cores, memory and the 1-minute load average (timings depend on it)."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = " ".join(line.split(":", 1)[1].split())
                break
    except OSError:
        pass
    parts = [cpu, f"{os.cpu_count()} cores"]
    try:
        parts.append(f"{os.sysconf('SC_PHYS_PAGES') * os.sysconf('SC_PAGE_SIZE') / 2**30:.0f} GiB")
        parts.append(f"load {os.getloadavg()[0]:.1f}")
    except (OSError, ValueError, AttributeError):
        pass
    return f"{platform.node()} ({', '.join(parts)})"


def format_value(value: float | None, unit: str = "") -> str:
    """A figure for a table: integers as such, else 3-4 significant digits."""
    if value is None:
        return "not measured"
    if value.is_integer() and abs(value) < 1e15:
        text = f"{int(value):,}"
    elif abs(value) >= 100:
        text = f"{value:,.1f}"
    elif abs(value) >= 10:
        text = f"{value:.2f}"
    else:
        text = f"{value:.3g}"
    return f"{text} {unit}".strip() if unit not in ("", "%") else text + unit


class Bench:
    """Collects one benchmark's figures and failures; see the module doc."""

    def __init__(
        self, benchmark: str, error_models: Mapping[str, str] | None = None, repo: Path = REPO
    ) -> None:
        self.benchmark = benchmark
        self.error_models = dict(error_models or {})
        self.started = now()
        self.commit = git_commit(repo)
        self.figures: list[Figure] = []
        self.failures: list[Failure] = []

    def figure(
        self,
        name: str,
        value: float | None,
        unit: str,
        *,
        goal: Goal | None = None,
        headline: bool = False,
        paper: float | None = None,
        note: str = "",
        error_models: Mapping[str, str] | None = None,
        missing: str = "",
    ) -> Figure:
        """Record a figure. ``value`` None (or not finite) means not measured:
        ``missing`` says why. ``error_models`` defaults to the benchmark's."""
        if value is not None and not math.isfinite(value):
            missing = missing or f"the measurement gave {value!r}"
            value = None
        if value is None and not missing:
            raise ValueError(f"figure {name!r}: not measured, and no reason given")
        target = None if goal is None else Target(goal.op, goal.value)
        v = verdict(value, target)
        if value is None:
            close = f"not measured: {missing}"
        else:
            close = goal.close if goal is not None and v == "missed" else ""
        fig = Figure(
            name=name,
            value=None if value is None else float(value),
            unit=unit,
            target=target,
            verdict=v,
            what_would_close_it=close,
            error_models=dict(self.error_models if error_models is None else error_models),
            date=now(),
            commit=self.commit,
            machine=machine(),
            headline=headline,
            paper=paper,
            note=note,
        )
        self.figures.append(fig)
        return fig

    def carry(self, path: Path, prefixes: Sequence[str]) -> BenchResult | None:
        """Keep the figures of the earlier results file ``path`` whose names begin
        with one of ``prefixes``, each with its own date and commit (a benchmark run
        again in part keeps the rest). Returns the earlier result, for its details;
        None, said on stdout, when the file is missing or unreadable."""
        try:
            old = load(path)
        except ResultError as exc:
            print(f"--keep: {exc}", flush=True)
            return None
        self.figures.extend(f for f in old.figures if f.name.startswith(tuple(prefixes)))
        return old

    def fail(self, experiment: str, reason: str) -> None:
        """Record an experiment that failed: the benchmark will exit non-zero."""
        self.failures.append(Failure(experiment, reason.strip() or "no reason given"))

    def result(self, details: Mapping[str, Any] | None = None) -> BenchResult:
        return BenchResult(
            schema=SCHEMA,
            benchmark=self.benchmark,
            started=self.started,
            finished=now(),
            commit=self.commit,
            machine=machine(),
            exit_code=1 if self.failures else 0,
            failures=list(self.failures),
            figures=list(self.figures),
            details=dict(details or {}),
        )

    def finish(
        self,
        path: Path | None,
        details: Mapping[str, Any] | None = None,
        out: TextIO | None = None,
    ) -> int:
        """Print the figures and their error models, write the JSON to ``path`` (when
        given) and return the exit status: 1 when an experiment failed, else 0."""
        res = self.result(details)
        print(summary(res), file=out or sys.stdout, flush=True)
        if path is not None:
            write(res, path)
        return res.exit_code


def spread(values: Sequence[float]) -> str:
    """How the seeds' values of one figure spread, for its note ("" for fewer than 2)."""
    if len(values) < 2:
        return ""
    sd = statistics.stdev(values)
    return f"mean of {len(values)} seeds, SD {sd:.3g}: " + ", ".join(f"{v:.3g}" for v in values)


def seed_runs(by_seed: Sequence[Sequence[float]]) -> tuple[list[float], str]:
    """Each seed's mean over its runs, and the note for the mean of those means.

    With one run per seed the note is :func:`spread`'s. With several it also says how
    far runs of one seed differ (their SD, pooled over the seeds): a simulated run is
    not repeatable (docs/simulation.md#calibration), and that SD is what thread timing
    alone moves one run's figure by."""
    seeds = [list(v) for v in by_seed if v]
    means = [statistics.mean(v) for v in seeds]
    n = max((len(v) for v in seeds), default=0)
    if n < 2:
        return means, spread(means)
    within = [statistics.variance(v) for v in seeds if len(v) > 1]
    pooled = math.sqrt(statistics.mean(within))
    head = f"mean of {len(means)} seeds x {n} runs"
    if len(means) > 1:
        head += f", SD {statistics.stdev(means):.3g} over the seeds' means"
    return means, (
        f"{head}: " + ", ".join(f"{v:.3g}" for v in means) + f"; SD {pooled:.3g} between "
        "runs of one seed"
    )


def target_text(t: Target | None, unit: str) -> str:
    return "–" if t is None else f"{t.op} {format_value(t.value, unit)}"


def summary(res: BenchResult) -> str:
    """Plain text: every figure with its target and verdict, what would close each
    miss, the failures, and the error models in force."""
    lines = [f"{res.benchmark} at {res.commit} on {res.machine}:"]
    for f in res.figures:
        mark = "* " if f.headline else "  "
        judged = (
            "no target"
            if f.target is None
            else f"target {target_text(f.target, f.unit)}: {f.verdict}"
        )
        lines.append(f"{mark}{f.name}: {format_value(f.value, f.unit)} ({judged})")
        if f.what_would_close_it and f.target is not None:
            lines.append(f"      what would close it: {f.what_would_close_it}")
        elif f.what_would_close_it:
            lines.append(f"      {f.what_would_close_it}")
    for fail in res.failures:
        lines.append(f"  FAILED {fail.experiment}: {fail.reason}")
    models: dict[str, str] = {}
    for f in res.figures:
        models.update(f.error_models)
    lines.append("error models in force:" + ("" if models else " none"))
    lines += [f"  {k}: {v}" for k, v in models.items()]
    return "\n".join(lines)
