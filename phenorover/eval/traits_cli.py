"""``phenorover eval traits RUN_DIR``: score a simulated survey's per-plot traits
against the simulator's plants.

Reads ``RUN_DIR/traits.csv`` (``phenorover traits``) and the plants' truth the
simulator wrote at its start (``plants.truth.json``, by default in the ``sim`` folder
beside the mission's: ``runs/sim/``, or ``--truth``), matches the plots by their id,
and prints and writes (``eval_traits.json`` in RUN_DIR) each trait's error
(:func:`phenorover.eval.traits.error`) over the plots flagged ok. The truth must be
of the same field and date as the survey: the simulator rewrites it when it starts
on another. Bad input is one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from common.canopy import TRAITS, column
from common.files import finite, write_atomic
from services.sim.truth_file import PLANTS_TRUTH

SCORED = ("height", "height_max", "cover", "volume_voxel", "volume_hull")
UNIT_SCALE = {"m": (100.0, "cm"), "1": (100.0, "%"), "m3": (1000.0, "L")}


class EvalError(ValueError):
    """The traits cannot be scored; one line naming the file and the cause."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run_dir", type=Path, help="where phenorover traits wrote traits.csv")
    p.add_argument("--truth", type=Path, default=None, help="plants.truth.json to score against")


def _read_traits(path: Path) -> list[dict[str, str]]:
    try:
        with path.open(newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
    except OSError as exc:
        raise EvalError(f"{path}: cannot read: {exc.strerror} (run `phenorover traits`)") from None
    need = {"plot", "quality", "date", *(column(t) for t in SCORED)}
    if not rows or not need <= set(rows[0]):
        raise EvalError(f"{path}: not a traits.csv (columns {sorted(need)})")
    return rows


def _read_truth(path: Path) -> dict[str, Any]:
    try:
        truth = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise EvalError(f"{path}: cannot read the plants' truth: {exc}") from None
    if not isinstance(truth, dict) or not truth.get("evaluation_only"):
        raise EvalError(f"{path}: not a plants' truth file")
    return truth


def _num(v: str | float | None) -> float:
    try:
        return float(v) if v not in (None, "") else math.nan
    except (TypeError, ValueError):
        return math.nan


def _same_definition(options: Path, truth: dict[str, Any], truth_path: Path) -> None:
    """The traits and the truth must follow one definition (``traits.toml``, the
    options the traits ran with; absent: not checked)."""
    import tomllib

    if not options.is_file():
        return
    try:
        ran = tomllib.loads(options.read_text(encoding="utf-8")).get("definition")
    except (OSError, ValueError) as exc:
        raise EvalError(f"{options}: cannot read: {exc}") from None
    if ran is not None and ran != truth.get("definition"):
        raise EvalError(
            f"{options}: the traits' definition {ran} is not the truth's "
            f"{truth.get('definition')} ({truth_path}): not the same measure"
        )


def evaluate(run_dir: Path, truth_path: Path) -> dict[str, Any]:
    """Each scored trait's errors; raises EvalError."""
    from phenorover.eval.traits import error

    rows = _read_traits(run_dir / "traits.csv")
    truth = _read_truth(truth_path)
    date = rows[0]["date"]
    if str(truth.get("date") or "") != date:
        raise EvalError(
            f"{truth_path}: the plants of {truth.get('date') or 'the mature stage'}, the "
            f"traits of {date or 'an unknown date'}: not the same survey"
        )
    _same_definition(run_dir / "traits.toml", truth, truth_path)
    by_id = {str(p["plot_id"]): p for p in truth["plots"]}
    missing = [r["plot"] for r in rows if r["plot"] not in by_id]
    if missing or len(by_id) != len(rows):
        raise EvalError(
            f"{truth_path}: the plants of field {truth.get('field')!r} do not match the "
            f"survey's plots ({len(by_id)} against {len(rows)}; {missing[:3]} not there)"
        )
    ok = np.array([r["quality"] == "ok" for r in rows])
    out: dict[str, Any] = {"date": date, "field": truth.get("field"), "plots_ok": int(ok.sum())}
    for t in SCORED:
        m = np.array([_num(r[column(t)]) for r in rows])
        v = np.array([_num(by_id[r["plot"]].get(t)) for r in rows])
        out[t] = error(m, v, ok).__dict__
    return out


def run(args: argparse.Namespace) -> int:
    truth = args.truth or args.run_dir.resolve().parent / "sim" / PLANTS_TRUTH
    try:
        res = evaluate(args.run_dir, truth)
    except EvalError as exc:
        print(f"phenorover eval traits: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    print(f"{args.run_dir}: {res['plots_ok']} plots ok, {res['date'] or 'undated'}")
    for t in SCORED:
        e = res[t]
        k, unit = UNIT_SCALE[TRAITS[t]]
        print(
            f"  {t}: RMSE {e['rmse'] * k:.2f} {unit}, bias {e['bias'] * k:+.2f} {unit}, "
            f"mean abs. error {e['mape']:.1f} % of the truth ({e['n']} plots)"
        )
    text = json.dumps(finite(res), indent=1, allow_nan=False)
    write_atomic(args.run_dir / "eval_traits.json", text.encode())
    return 0
