"""``phenorover traits RUN_DIR...`` (also ``python -m services.traits RUN_DIR``).

Reads a registered run folder (``mission.db`` read-only, its plan's field and field
book, ``registered.laz`` from ``phenorover register``), finds the ground, computes
every plot's traits and writes into ``RUN_DIR`` (or ``--out``) ``traits.csv``,
``traits_long.csv``, ``traits.geojson``, ``fieldmap.png`` and ``traits.toml`` (the
options it ran with: :mod:`.config`, the manifest's ``[services.traits]``,
``--config``, ``--set`` and the flags). See :mod:`.outputs` for the files and
:mod:`.run` for where the survey date comes from (``--date`` overrides it).

Several run folders of one field: a season (:mod:`.series`), written into ``--out``
(default: ``season-<field>`` beside the last run): the season's files
(:mod:`.season_outputs`) and each date's own in ``<out>/<run folder name>``.

Every file is written under a temporary name and renamed when complete, so an
interrupted run leaves the previous outputs (or none), never half a file. Bad input
is one error line on stderr and exit status 2, before anything of that run is
written.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import sys
import time
from pathlib import Path

from common.cluster import Cluster, ClusterError, add_cluster_arguments, cluster_of
from services.traits.compute import NO_POINTS, OCCLUDED, OK, RunTraits, compute_traits, read_run
from services.traits.config import TraitsConfig, add_config_arguments, resolve
from services.traits.fits import Fits
from services.traits.outputs import write_outputs
from services.traits.run import RunError

log = logging.getLogger("phenorover.traits")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "run_dir", type=Path, nargs="+", help="a registered mission's folder: runs/<mission>"
    )
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="output folder (default: RUN_DIR; with several runs, OUT/<run folder name>)",
    )
    p.add_argument(
        "--date",
        default=None,
        metavar="YYYY-MM-DD",
        help="the survey's date (default: the mission's clock, else the simulated "
        "trial's date in RUN_DIR/manifest.toml)",
    )
    add_config_arguments(p)
    add_cluster_arguments(p, "a season's runs (one run is computed here)")


def run_traits(
    run_dir: Path, cfg: TraitsConfig, out: Path | None = None, date: str | None = None
) -> tuple[RunTraits, list[str]]:
    """Compute one run's traits and write its outputs into ``out`` (default:
    ``run_dir``); returns them and the names of the files written. Raises RunError.
    The heritabilities are fitted in a worker process (:mod:`.fits`) when the field
    book names entries."""
    inp, read = read_run(run_dir, date)
    with contextlib.ExitStack() as stack:
        fits = stack.enter_context(Fits()) if any(r.entry for r in inp.records) else None
        rt = compute_traits(inp, cfg)
        rt.timings["read"] = read
        t = time.perf_counter()
        if fits is not None:
            fits.submit(rt.table)
        names = write_outputs(rt, cfg, out or run_dir, None if fits is None else fits.next)
    rt.timings["write"] = time.perf_counter() - t
    log.info("wrote %s (%.1f s)", ", ".join(names), rt.timings["write"])
    return rt, names


def _summary(rt: RunTraits, out: Path, seconds: float) -> str:
    q = rt.table.quality
    flags = ", ".join(f"{q.count(k)} {k}" for k in (OK, OCCLUDED, NO_POINTS) if q.count(k))
    when = rt.date or "date unknown"
    return (
        f"traits of {rt.run_dir} ({when}): {len(q)} plots ({flags}) in {seconds:.1f} s: "
        f"{out / 'traits.csv'}"
    )


def run_season(
    runs: list[Path], cfg: TraitsConfig, out: Path | None, cluster: Cluster | None = None
) -> Path:
    """A season of ``runs``, written into ``out`` (default: ``season-<field>`` beside
    the last run): the season's files, and each date's own in ``out/<run>``. Not into
    the runs' folders: a date's heights here stand on the season's first ground, so
    they would change the run's own outputs with whichever season read it last.
    ``cluster``: where the runs are read and computed (a Dask cluster whose workers
    see the run folders)."""
    from services.traits.season_outputs import write_season
    from services.traits.series import forget, season

    t0 = time.monotonic()
    with Fits() as fits:
        try:
            s = season(runs, cfg, None if cluster is None else cluster.map)
        finally:
            if cluster is not None:
                cluster.everywhere(forget)
        dest = out or s.runs[-1].run_dir.parent / f"season-{s.runs[0].layout.name}"
        entries = any(r.entry for r in s.runs[0].records)
        for rt in s.runs if entries else ():
            fits.submit(rt.table)
        for rt in s.runs:
            write_outputs(rt, cfg, dest / rt.run_dir.name, fits.next if entries else None)
            print(_summary(rt, dest / rt.run_dir.name, sum(rt.timings.values())), flush=True)
    names = write_season(s, dest, cfg.figures)
    print(
        f"season of {len(s.runs)} dates ({s.runs[0].date} to {s.runs[-1].date}) in "
        f"{time.monotonic() - t0:.1f} s: {', '.join(str(dest / n) for n in names[:1])}",
        flush=True,
    )
    return dest


def cmd_traits(args: argparse.Namespace) -> int:
    runs: list[Path] = list(args.run_dir)
    try:
        cfg, _ = resolve(args)
        if len(runs) > 1:
            if args.date is not None:
                raise RunError("--date names one survey's date: give it with one RUN_DIR")
            with cluster_of(args) as cluster:
                run_season(runs, cfg, args.out, cluster)
            return 0
        t0 = time.monotonic()
        rt, _ = run_traits(runs[0], cfg, args.out, args.date)
        print(_summary(rt, args.out or runs[0], time.monotonic() - t0), flush=True)
    except (RunError, ValueError, OSError, ClusterError) as exc:
        print(f"phenorover traits: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    return 0


def add_command(p: argparse.ArgumentParser) -> None:
    """``phenorover traits``."""
    add_arguments(p)
    p.set_defaults(func=cmd_traits)


def main(argv: list[str] | None = None) -> int:
    from common.service_args import run_tool

    return run_tool("traits", __doc__, add_arguments, cmd_traits, argv)
