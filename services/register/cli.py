"""``phenorover register RUN_DIR`` (also ``python -m services.register RUN_DIR``).

Reads ``RUN_DIR/mission.db`` (read-only) and the scans it lists, places every scan by
its recorded navigation pose and inclinometer (paper eq. 1), refines all scans jointly
cloud to cloud, solves the target-based reference from the spheres, and writes into
``RUN_DIR`` (or ``--out``):

- ``registered.e57``: every scan with its final pose (CloudCompare, FARO SCENE);
- ``registered.laz``: all scans merged and voxel-downsampled in the field frame (what
  the viz service shows), and ``utm.laz`` in UTM when the field is georeferenced;
- ``report.json``, ``report.md`` and the PNG figures of :mod:`.figures`;
- ``register.toml``: the options it ran with (:mod:`.config`: the manifest's
  ``[services.register]``, ``--config``, ``--set`` and the flags).

It reads nothing but what a real robot records: the mission log, the scans and the
options. Scoring against a simulator's truth is ``phenorover eval register``.

Every file is written under a temporary name and renamed when complete, so an
interrupted registration leaves the previous outputs (or none), never half a file.
Bad input is one error line on stderr and exit status 2; see :mod:`.runlog`.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path
from typing import Any

import msgspec

from common.cluster import Cluster, ClusterError, add_cluster_arguments, cluster_of
from common.config import dump_toml
from common.files import finite, write_atomic
from common.robot import RUN_COPY, load_robot
from services.register.config import RegisterRunConfig, add_config_arguments, resolve
from services.register.outcome import Registration
from services.register.pipeline import register
from services.register.report import build_report
from services.register.report_md import markdown
from services.register.runlog import Placement, RunData, RunError, load_run, scan_inputs

log = logging.getLogger("phenorover.register")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run_dir", type=Path, help="a mission's folder: runs/<mission>")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: RUN_DIR)")
    p.add_argument(
        "--scans",
        type=Path,
        action="append",
        default=[],
        metavar="DIR",
        help="where to look for scan files missing at their recorded path (repeatable)",
    )
    add_config_arguments(p)
    add_cluster_arguments(p, "the scan pairs' alignments")
    p.add_argument(
        "--robot",
        default=None,
        help=f"robot description (default: RUN_DIR/{RUN_COPY}, kept by the mission, "
        "else the shipped Husky)",
    )


def write_outputs(run: RunData, reg: Registration, cfg: RegisterRunConfig, out: Path) -> None:
    """The E57, the LAZ files, the report and its figures (see the module docstring)."""
    from common.pointcloud import voxel_merge, write_e57, write_merged_laz
    from services.register import figures

    out.mkdir(parents=True, exist_ok=True)
    outputs: dict[str, Any] = {}
    t = time.perf_counter()
    write_e57(out / "registered.e57", reg.scans)
    outputs["e57"] = "registered.e57"
    log.info("wrote %s (%.1f s)", out / "registered.e57", time.perf_counter() - t)
    merged = voxel_merge(reg.scans, cfg.laz_voxel)  # once for both frames
    n_points = write_merged_laz(out / "registered.laz", merged)
    outputs["laz_field"] = "registered.laz"
    layout = None if run.plan is None else run.plan.layout
    if layout is not None and layout.georeferenced:
        from common.field_geojson import field_frame

        frame = field_frame(layout)
        epsg = frame.utm.to_epsg()
        write_merged_laz(out / "utm.laz", merged, frame.field_to_utm, epsg)
        outputs["laz_utm"] = "utm.laz"
        outputs["utm_epsg"] = epsg
    outputs["laz_points"] = n_points
    log.info("wrote merged LAZ (%d points at %.0f mm)", n_points, cfg.laz_voxel * 1000)
    figs: list[str] = []
    if cfg.figures:
        for make in (
            lambda: figures.layout_route(run, out),
            lambda: figures.stationary(run, out),
            lambda: figures.registration_hist(reg, out),
        ):
            name = make()
            if name:
                figs.append(name)
        log.info("wrote figures: %s", ", ".join(figs))
    write_atomic(out / "register.toml", dump_toml(cfg).encode())
    outputs["config"] = "register.toml"
    write_report(run, reg, out, outputs, figs)


def write_report(
    run: RunData, reg: Registration | None, out: Path, outputs: dict[str, Any], figs: list[str]
) -> dict[str, Any]:
    """``report.json`` and ``report.md`` from the mission log and the registration."""
    rep = build_report(run, None if reg is None else reg.report, outputs)
    text = json.dumps(finite(rep), indent=1, allow_nan=False)
    write_atomic(out / "report.json", text.encode())
    write_atomic(out / "report.md", markdown(rep, figs).encode())
    return rep


def run_register(
    run_dir: Path,
    out: Path | None = None,
    scan_dirs: list[Path] | None = None,
    cfg: RegisterRunConfig | None = None,
    robot: str | Path | None = None,
    cluster: Cluster | None = None,
) -> Registration:
    """Register one run folder and write its outputs; raises RunError or ValueError
    (ConfigError for a bad robot description). ``robot``: see ``--robot``;
    ``cluster``: where the scan pairs are aligned (default: here)."""
    cfg = cfg or RegisterRunConfig()
    run = load_run(run_dir)
    if robot is None:
        copy = Path(run_dir) / RUN_COPY
        robot = copy if copy.is_file() else ""
    inputs = scan_inputs(run, Placement.of(load_robot(robot)), scan_dirs or [])
    log.info("mission %s: %d scans to register", run.mission["id"], len(inputs))
    if not run.has_altitude:
        log.warning("the mission log has no altitude (z = 0): heights come from C2C only")
    rcfg = cfg.register
    if not run.has_altitude:
        # a zero altitude is no measurement: let the clouds decide the heights
        rcfg = msgspec.structs.replace(
            rcfg, refine=msgspec.structs.replace(rcfg.refine, nav_sigma_z=1.0)
        )
    pairs_by = None
    if cluster is not None:
        from services.register.cluster import DaskPairs

        pairs_by = DaskPairs([s.path for s in inputs], rcfg.refine, cluster)
    reg = register(inputs, rcfg, pairs_by)
    write_outputs(run, reg, cfg, out or run_dir)
    return reg


def cmd_register(args: argparse.Namespace) -> int:
    t0 = time.monotonic()
    try:
        cfg, _ = resolve(args)
        with cluster_of(args) as cluster:
            run_register(args.run_dir, args.out, args.scans, cfg, args.robot, cluster)
    except (RunError, ValueError, OSError, ClusterError) as exc:
        print(f"phenorover register: {exc}", file=sys.stderr)
        return 2
    print(
        f"registered {args.run_dir} in {time.monotonic() - t0:.0f} s: "
        f"{(args.out or args.run_dir) / 'report.md'}",
        flush=True,
    )
    return 0


def add_command(p: argparse.ArgumentParser) -> None:
    """``phenorover register``."""
    add_arguments(p)
    p.set_defaults(func=cmd_register)


def main(argv: list[str] | None = None) -> int:
    from common.service_args import run_tool

    return run_tool("register", __doc__, add_arguments, cmd_register, argv)
