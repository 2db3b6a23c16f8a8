"""The calibration table of docs/results.md: for each of the paper's field figures,
the paper's method in our simulator (the baseline profile) and ours in the same
world, side by side, read from the benchmarks' JSON (bench_profiles: the navigation
experiments; bench_survey: the ENGR survey and its registration).

Each row names its figures as those benchmarks do, so a figure renamed there shows
here as not measured (and a test of the committed JSON fails) rather than vanishing.
Runs no benchmark; computes nothing the benchmarks did not.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from phenorover.eval.bench_schema import Figure, ResultError, load
from phenorover.eval.results import format_value, target_text

HEADING = "## Calibration: the paper's field, its method and ours in the simulator"
# how the benchmarks name their comparisons (they take these names from here): a
# figure's name followed by AGAINST_PAPER is the baseline's distance from the paper's
# figure, followed by OURS_AGAINST is ours over the baseline's
AGAINST_PAPER = ": the paper's method in our sim against the paper's field figure"
OURS_AGAINST = ": ours against the paper's method"
SURVEY_OURS_AGAINST = "nav + C2C mean point error: ours (make sim) against the paper's method"
SURVEY_BASE = "make sim with the paper's method (sim.toml), field engr: "
SURVEY_OURS = "make sim (sim.toml), field engr: "
OVERLAP = "between overlapping scans (SCENE's scan point statistics, the paper's metric; no truth)"


@dataclass(frozen=True)
class Row:
    """One line of the table: the benchmark and its figures' names (None: it has
    none of that kind)."""

    bench: str
    baseline: str
    ours: str
    against_paper: str | None = None  # the baseline's distance from the paper's figure
    ours_against_baseline: str | None = None


def _profiles(label: str, compared: bool = True, ratio: bool = False) -> Row:
    return Row(
        "bench_profiles",
        f"{label} [paper]",
        f"{label} [ours]",
        f"{label}{AGAINST_PAPER}" if compared else None,
        f"{label}{OURS_AGAINST}" if ratio else None,
    )


def _survey(label: str, compared: str | None = None, ratio: str | None = None) -> Row:
    return Row(
        "bench_survey",
        SURVEY_BASE + label,
        SURVEY_OURS + label,
        f"{compared}{AGAINST_PAPER}" if compared else None,
        ratio,
    )


ROWS = (
    _profiles("border: mean cross-track error, true pose", ratio=True),
    _profiles("border: 99th percentile of cross-track error, true pose", compared=False),
    _profiles("border: share of the path below 5 cm"),
    _profiles("serpentine: mean cross-track error, true pose", ratio=True),
    _profiles("serpentine: 99th percentile of cross-track error, true pose", compared=False),
    _profiles("stationary: estimate against the planned point (the paper's metric)"),
    _profiles("stationary: estimate's heading residual (the paper's metric)"),
    _profiles("stationary: true stop against the planned point", compared=False),
    _survey(
        "navigation alone (pre-alignment): largest point error against the truth",
        compared="pre-alignment's largest point error",
    ),
    _survey(
        f"nav + C2C: mean point error {OVERLAP}",
        compared="nav + C2C mean point error between overlapping scans (SCENE's)",
    ),
    _survey(
        f"target-based: mean point error {OVERLAP}",
        compared="target-based mean point error between overlapping scans (SCENE's)",
    ),
    _survey(
        "nav + C2C cloud against the target-based cloud: mean distance",
        compared="nav + C2C cloud to the target-based one, mean",
    ),
    _survey(
        "nav + C2C cloud against the target-based cloud: SD distance",
        compared="nav + C2C cloud to the target-based one, SD",
    ),
    _survey(
        "nav + C2C: mean point error against the truth",
        ratio=SURVEY_OURS_AGAINST,
    ),
    _survey("true stop at each scan against its planned location, mean"),
)
BENCHES = tuple(sorted({r.bench for r in ROWS}))


def _value(f: Figure | None, spread: bool = True) -> str:
    """A figure's cell: its value, its target and verdict when it has one, and how
    its seeds spread (the figure's note)."""
    if f is None:
        return "not measured"
    text = format_value(f.value, f.unit)
    if f.target is not None:
        text += f" ({target_text(f.target, f.unit)}: {f.verdict})"
    if spread and f.note:
        text += f" ({f.note})"
    return text.replace("|", "\\|")


def section(bench_dir: Path) -> list[str]:
    """The table, or a line saying which benchmark's JSON is missing."""
    figures: dict[str, dict[str, Figure]] = {}
    for bench in BENCHES:
        try:
            figures[bench] = {f.name: f for f in load(bench_dir / f"{bench}.json").figures}
        except ResultError as exc:
            return [HEADING, "", f"No table: {exc}. `make bench` writes it.", ""]
    out = [
        HEADING,
        "",
        "The paper's field figures (arXiv:2404.04404), the paper's method as a profile of "
        "our services (the baseline) and ours, on the same calibrated world and seeds; "
        "gathered from the tables of `bench_profiles` and `bench_survey` below, which give "
        "each figure's error models, date and commit. The baseline should lie within 25 % "
        "of each paper figure; where it cannot, [simulation.md](simulation.md#calibration) "
        "says why.",
        "",
        "| figure | the paper's field | the paper's method in our sim | ours in our sim "
        "| baseline against the paper | ours against the baseline | measured |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in ROWS:
        got = figures[r.bench]
        base = got.get(r.baseline)
        name = r.baseline.removesuffix(" [paper]").removeprefix(SURVEY_BASE)
        paper = "–" if base is None or base.paper is None else format_value(base.paper, base.unit)
        cells = [
            name,
            paper,
            _value(base),
            _value(got.get(r.ours)),
            _value(got.get(r.against_paper), spread=False) if r.against_paper else "–",
            _value(got.get(r.ours_against_baseline)) if r.ours_against_baseline else "–",
            "–" if base is None else f"{r.bench}, {base.date[:10]}, {base.commit}",
        ]
        out.append("| " + " | ".join(cells) + " |")
    return [*out, ""]
