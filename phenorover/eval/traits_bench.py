"""The traits benchmark's figures (``tests/bench/bench_traits.py``): targets, error
models and the figures of :mod:`phenorover.eval.traits`' scores, each the mean over
the seeds with their spread."""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from typing import Any

from phenorover.eval.results import Bench, Goal, spread
from phenorover.eval.traits import SeedScore

TARGETS = {
    "height_rmse_cm": 2.0,
    "cover_mape_pct": 5.0,
    "volume_mape_pct": 5.0,
    "growth_rmse_cm": 2.0,
    "h2_abs_diff": 0.05,
    "one_s": 10.0,
    "season_s": 30.0,
}


def error_models(
    step_deg: float, nav: dict[str, float], trial: Any, foliage_voxel: float
) -> dict[str, str]:
    """The models the traits benchmark draws under: the survey's (navigation, FARO,
    terrain: as the registration benchmark) and the trial's growth and variation."""
    from phenorover.eval.error_models import faro, terrain
    from services.sim.world_config import WorldConfig

    w = WorldConfig()
    return {
        "navigation pose (drawn per scan)": (
            f"{100 * nav['xy_m']:g} cm horizontal, {100 * nav['z_m']:g} cm vertical, "
            f"{nav['yaw_deg']:g} deg heading (1 sigma, independent per scan)"
        ),
        **faro(w.scanner_noise, nav["tilt_deg"]),
        **terrain(w.terrain),
        "scan": f"{step_deg:g} deg steps from the planner's locations: 70 days on the "
        "nominal boxes, 91 days on the crop the survey of 70 days measured (beside it: "
        "on the nominal boxes)",
        "plants": f"foliage in {foliage_voxel * 100:g} cm voxels; true heights are their top faces",
        "trial (services.sim.trial, assumptions)": (
            f"logistic growth, rate {trial.rate_per_day:g}/day, inflection "
            f"{trial.inflection_days:g} days; genetic sd height/width/density "
            f"{trial.entry_sd_height:g}/{trial.entry_sd_width:g}/{trial.entry_sd_density:g}, "
            f"plot sd {trial.plot_sd_height:g}/{trial.plot_sd_width:g}/"
            f"{trial.plot_sd_density:g} (log scale); gaps {trial.gap_rate:.0%} (runs "
            f"{trial.gap_run:g}); {trial.lean_share:.0%} of plants leaning "
            f"{trial.lean_deg_min:g}-{trial.lean_deg_max:g} deg"
        ),
    }


def _fig(bench: Bench, name: str, values: list[float], unit: str, **kw: Any) -> None:
    vals = [v for v in values if math.isfinite(v)]
    value = statistics.mean(vals) if vals else None
    note = spread(vals)
    bench.figure(name, value, unit, note=note, missing="no seed measured it", **kw)


def record_scores(bench: Bench, seeds: Sequence[SeedScore]) -> None:
    """The accuracy figures, each the mean over the seeds with their spread."""
    close = {
        "height": "a view of the canopy's top: once the crop outgrows the 1 m scanner it "
        "sees the sides of each plot's top, not its tallest tips (heights fall short, "
        "bias below); a scanner raised above the crop, or more scan locations along the "
        "lanes than the plan on the measured crop asks for",
        "cover": "scan locations that see each plot from both lanes",
        "volume": "the voxels behind the surface are inferred, not seen: one a ray "
        "crossed counts as empty though a loose edge may hold a leaf (plots seen well "
        "fall short), one no ray reached inside the canopy's hull as occupied; more scan "
        "locations along the lanes, or an occupancy learnt from the rays that did reach "
        "into the canopy",
        "h2": "a smaller height error (the plot noise it adds lowers H2)",
    }
    for k, label in enumerate(DATE_LABELS):
        errs = [s.errors[k] for s in seeds if k < len(s.errors)]
        _fig(
            bench,
            f"canopy height RMSE against the truth ({label})",
            [e["height"].rmse * 100 for e in errs],
            "cm",
            goal=Goal("<=", TARGETS["height_rmse_cm"], close["height"]),
            headline=k == len(DATE_LABELS) - 1,
        )
        _fig(bench, f"canopy height bias ({label})", [e["height"].bias * 100 for e in errs], "cm")
        _fig(
            bench,
            f"projected cover, mean abs. error per plot ({label})",
            [e["cover"].mape for e in errs],
            "%",
            goal=Goal("<=", TARGETS["cover_mape_pct"], close["cover"]),
        )
        for t, name in (("volume_voxel", "voxel volume"), ("volume_hull", "hull volume")):
            _fig(
                bench,
                f"{name}, mean abs. error per plot ({label})",
                [e[t].mape for e in errs],
                "%",
                goal=Goal("<=", TARGETS["volume_mape_pct"], close["volume"])
                if t == "volume_voxel"
                else None,
            )
        _fig(
            bench,
            f"plots left out as occluded or empty ({label})",
            [float(e["height"].flagged) for e in errs],
            "plots",
        )
    _fig(
        bench,
        "growth in height between the dates, RMSE against the true growth",
        [s.growth.rmse * 100 for s in seeds],
        "cm",
        goal=Goal("<=", TARGETS["growth_rmse_cm"], close["height"]),
        headline=True,
    )
    _fig(
        bench,
        "heritability (entry-mean H2) of height: |measured - true|, same plots",
        [abs(s.h2_measured - s.h2_true) for s in seeds],
        "",
        goal=Goal("<=", TARGETS["h2_abs_diff"], close["h2"]),
        headline=True,
    )
    _fig(bench, "heritability of height, measured", [s.h2_measured for s in seeds], "")
    _fig(
        bench,
        "heritability of height, true plants, the same plots",
        [s.h2_true for s in seeds],
        "",
    )
    _fig(
        bench,
        "heritability of height, true plants, every plot (flagged ones too)",
        [s.h2_true_all for s in seeds],
        "",
    )


def record_beside(bench: Bench, seeds: Sequence[SeedScore]) -> None:
    """Like for like: the second date flown on the plan on the nominal boxes, as the
    seeds of :func:`record_scores` flew it on the plan from the first survey."""
    label = f"{DATE_LABELS[-1].split(' (')[0]}, flown on the nominal plan"
    errs = [s.errors[-1] for s in seeds if s.errors]
    rows: list[tuple[str, list[float], str]] = [
        ("canopy height RMSE against the truth", [e["height"].rmse * 100 for e in errs], "cm"),
        ("canopy height bias", [e["height"].bias * 100 for e in errs], "cm"),
        ("projected cover, mean abs. error per plot", [e["cover"].mape for e in errs], "%"),
        ("voxel volume, mean abs. error per plot", [e["volume_voxel"].mape for e in errs], "%"),
        ("hull volume, mean abs. error per plot", [e["volume_hull"].mape for e in errs], "%"),
        ("plots left out", [float(e["height"].flagged) for e in errs], "plots"),
        ("growth in height, RMSE", [s.growth.rmse * 100 for s in seeds], "cm"),
        ("H2 of height, |measured - true|", [abs(s.h2_measured - s.h2_true) for s in seeds], ""),
    ]
    for name, values, unit in rows:
        _fig(bench, f"{name} ({label})", values, unit)


def record_times(bench: Bench, one: float | None, five: float | None, why: str = "") -> None:
    """``phenorover traits`` wall times (one seed's runs)."""
    for what, value, target, close in (
        (
            "one 60-plot survey",
            one,
            "one_s",
            "the field map and the six heritability fits drawn and fitted on the second "
            "core while the rays are walked",
        ),
        ("a season of five dates", five, "season_s", "the dates read and computed in parallel"),
    ):
        bench.figure(
            f"phenorover traits, {what} (wall, the command)",
            value,
            "s",
            goal=Goal("<=", TARGETS[target], close),
            headline=True,
            missing=why,
        )


def record_plan(
    bench: Bench, cmp: dict[str, Any] | None, nominal: Any, measured: Any, why: str = ""
) -> None:
    """The next survey planned on the crop a survey measured (70 days after planting)
    against the plan on the nominal boxes, both scored in the world of the next
    survey (91 days): the true foliage cells each plan's scans see, and what each plan
    spends for it (its locations and tour), side by side."""
    base = None if cmp is None else 100 * cmp["nominal"]["share"]
    for name, plan in (("nominal", nominal), ("measured", measured)):
        c = None if cmp is None else cmp[name]
        where = f"plan on the {name} boxes" + (" (crop of 70 days)" if name == "measured" else "")
        goal = None
        if name == "measured" and base is not None:
            goal = Goal(">=", base, "more scan locations where the measured crop is hidden")
        missing = why or "not measured"
        bench.figure(
            f"true foliage cells seen at 91 days, {where}",
            None if c is None else 100 * c["share"],
            "%",
            note=""
            if c is None or cmp is None
            else (f"{c['cells_seen']} of {cmp['cells_total']} true cells"),
            missing=missing,
            goal=goal,
            headline=name == "measured",
        )
        bench.figure(
            f"scan locations, {where}",
            None if c is None else float(c["locations"]),
            "",
            missing=missing,
        )
        bench.figure(
            f"tour length, {where}",
            None if plan is None else float(plan.tour.length),
            "m",
            missing=missing,
        )


DATE_LABELS = (
    "70 days after planting (plan on the nominal boxes)",
    "91 days after planting (plan on the crop of 70 days)",
)
