"""The ``phenorover`` command: run deployments, ask who is alive, run the simulation,
make the deployment's certificates."""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from common.client import (
    DEFAULT_MANIFEST,
    add_connection_arguments,
    connect_or_explain,
    open_client,
    wait_alive,
)
from common.config import ConfigError
from common.service_args import setup_logging
from common.status import format_table, query_alive
from phenorover.cpu import CpuUse, Mark

if TYPE_CHECKING:
    from common.messages.mission import MissionState
    from common.messages.sim import SimClock
    from common.streams import Latest
    from common.transport import Bus
    from phenorover.launcher import Launcher

log = logging.getLogger("phenorover")


def cmd_up(args: argparse.Namespace) -> int:
    if args.check:
        return cmd_check(args.manifest)
    from phenorover.launcher import up

    return up(args.manifest)


def cmd_check(manifest: Path) -> int:
    """``up --check``: what each service would open; exit 2 with a line per problem."""
    from phenorover.findings import check

    try:
        report, problems = check(manifest)
    except ConfigError as exc:
        print(f"phenorover up --check: {exc}", file=sys.stderr)
        return 2
    print("\n".join(report), flush=True)
    for line in problems:
        print(f"phenorover up --check: {line}", file=sys.stderr)
    if problems:
        return 2
    print(f"{manifest}: ready to start")
    return 0


def cmd_certs(args: argparse.Namespace) -> int:
    from phenorover.certs import CertError, init_ca, issue_files

    hosts = [*args.host, *(("localhost", "127.0.0.1") if args.loopback else ())]
    try:
        if args.days is not None and args.days < 1:
            raise CertError(f"--days {args.days}: must be at least 1")
        if args.action == "init":
            if args.machine is not None:
                raise CertError("certs init makes the CA; `certs issue MACHINE` a machine's")
            written = init_ca(args.dir, force=args.force, days=args.days or 3650)
        elif args.machine is None:
            raise CertError("certs issue: name the machine (e.g. robot)")
        else:
            written = issue_files(args.machine, args.dir, hosts, args.force, args.days or 825)
    except CertError as exc:
        print(f"phenorover certs: {exc}", file=sys.stderr)
        return 2
    for p in written:
        print(f"wrote {p}")
    return 0


def cmd_status(args: argparse.Namespace) -> int:
    session = connect_or_explain("phenorover status", args.manifest, args.connect)
    if session is None:
        return 2
    with session:
        entries = query_alive(session, timeout=args.timeout)
    print(format_table(entries) if entries else "no phenorover service is alive")
    return 0 if entries else 1


def cmd_sim(args: argparse.Namespace) -> int:
    """The simulated deployment: all services alive, then (unless --alive-only) a
    whole survey of the field, with a line per step and a summary.

    ``--field`` is the field of the whole deployment, not only of the survey: every
    service (the simulated world included) is started with it. Exit status: 0 when
    every location was scanned, 1 when the survey failed or left a location unscanned
    (each named with the reason), 2 on a bad manifest or field, found before anything
    starts (:func:`phenorover.preflight.preflight`, with the field given)."""
    from common import keys
    from common.transport import Bus
    from phenorover.eval.truth_view import beside
    from phenorover.launcher import Launcher, held_world, release_world
    from services.mission.cli import run_survey

    field = args.field or None
    if field and Path(field).exists():  # one file for every service, whatever its cwd
        field = str(Path(field).resolve())
    try:
        # in lockstep the world is held until the survey has started
        held = held_world(args.manifest)
        launcher = Launcher(args.manifest, field=field, extra_args=held)
    except ConfigError as exc:
        print(f"phenorover sim: {exc}", file=sys.stderr)
        return 2
    field = launcher.manifest.field
    for note in launcher.notes:
        print(note, flush=True)
    wanted = set(launcher.children)
    t0 = time.monotonic()
    # the served dashboard shows the robot's estimate; the simulator's truth is added
    # to its recording by the evaluation's overlay
    with (
        launcher,
        open_client(args.manifest, []) as session,
        beside(args.manifest, launcher.manifest),
    ):
        alive = wait_alive(session, wanted, timeout=args.timeout)
        print(format_table(alive.seen), flush=True)
        if not alive:
            print(f"phenorover sim: not alive after {args.timeout:g} s: {sorted(alive.missing)}")
            return 1
        print(f"all {len(wanted)} services alive after {time.monotonic() - t0:.1f} s")
        if args.alive_only:
            return 0
        bus = Bus(session, "sim-cli")
        problems: list[str] = []
        clock = bus.latest(keys.SIM_CLOCK)
        try:
            release = (lambda: release_world(bus)) if held else None
            start = _mark(launcher, clock)
            final = run_survey(bus, field, args.survey_timeout, problems, args.new, release)
            if final is not None:
                use = CpuUse.between(start, _mark(launcher, clock))
                print(use.line(), flush=True)
                use.write(Path(launcher.manifest.run_dir) / final.mission / "cpu.json")
                _idle(bus)
                from services.mission.registration import wait_registration

                final = wait_registration(bus, final, args.register_timeout)
        finally:
            bus.close()
        if final is None:
            return 1
        return _verdict(final, problems, Path(launcher.manifest.run_dir), time.monotonic() - t0)


def _verdict(final: MissionState, problems: list[str], run_dir: Path, wall: float) -> int:
    """The survey's summary line, what went wrong on stderr; ``phenorover sim``'s exit
    status (0: every location scanned, else 1)."""
    from services.mission.cli import describe

    print(f"summary: {describe(final)}; wall {wall:.0f} s; files in {run_dir / final.mission}")
    complete = final.scans_done == final.scans_total and final.scans_failed == 0
    if final.phase.value == "done" and complete:
        return 0
    for text in problems:
        print(f"phenorover sim: {text}", file=sys.stderr)
    if not complete:
        print(
            f"phenorover sim: {final.scans_total - final.scans_done} of "
            f"{final.scans_total} locations not scanned (mission.db in "
            f"{run_dir / final.mission})",
            file=sys.stderr,
        )
    return 1


def _idle(bus: Bus) -> None:
    """Pace the world at real time from now on: its robot only stands while the scans
    are registered, and the registration gets the CPU the world's speed took."""
    from common import keys
    from common.messages.sim import SimRun
    from common.rpc import RpcError

    try:
        bus.call(keys.SIM_RUN, SimRun(real_time_factor=1.0), timeout=10)
    except RpcError as exc:  # the registration only runs slower
        print(f"phenorover sim: the world kept its pace: {exc}", file=sys.stderr)


def _mark(launcher: Launcher, clock: Latest[SimClock]) -> Mark:
    """Now, by the wall, the world's clock and each service's CPU."""
    c = clock.get()
    return Mark(time.monotonic(), c.sim_ns / 1e9 if c is not None else 0.0, launcher.cpu())


# command -> (module with ``add_command(parser)``, help): imported when the command runs
LAZY = {
    "plan": ("services.planner.cli", "plan scan locations and the route for a field"),
    "nav-test": ("phenorover.eval.navtest", "run one of the paper's navigation experiments"),
    "mission": ("services.mission.cli", "control the mission service"),
    "register": ("services.register.cli", "register a mission's scans and write its report"),
    "traits": ("services.traits.cli", "per-plot canopy traits of a registered survey"),
    "eval": ("phenorover.eval.cli", "score a simulated run against the simulator's truth"),
}


def _command(argv: Sequence[str] | None) -> str | None:
    """The command ``argv`` names (None: none, e.g. ``--help``), before parsing."""
    pre = argparse.ArgumentParser(add_help=False)
    pre.add_argument("--log-level")
    pre.add_argument("cmd", nargs="?")
    known, _ = pre.parse_known_args(sys.argv[1:] if argv is None else argv)
    return known.cmd


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="phenorover", description=__doc__)
    p.add_argument("--log-level", default="info")
    sub = p.add_subparsers(dest="cmd", required=True)

    s = sub.add_parser("up", help="run the services of a manifest on this machine")
    s.add_argument("manifest", type=Path)
    s.add_argument(
        "--check",
        action="store_true",
        help="start nothing: say what each service would open, exit 2 if anything is missing",
    )
    s.set_defaults(func=cmd_up)

    from phenorover.certs import DEFAULT_DIR

    s = sub.add_parser("certs", help="make the CA and the machines' TLS certificates")
    s.add_argument("action", choices=["init", "issue"], help="init: the CA; issue: a machine's")
    s.add_argument("machine", nargs="?", default=None, help="issue: the machine (common name)")
    s.add_argument("--dir", type=Path, default=DEFAULT_DIR, help=f"default: {DEFAULT_DIR}")
    s.add_argument("--host", action="append", default=[], help="another name or address")
    s.add_argument("--loopback", action="store_true", help="also valid as localhost, 127.0.0.1")
    s.add_argument("--force", action="store_true", help="replace existing files")
    s.add_argument("--days", type=int, default=None, help="validity (CA 3650, machine 825)")
    s.set_defaults(func=cmd_certs)

    s = sub.add_parser("status", help="which services are alive, where, since when")
    add_connection_arguments(s)
    s.add_argument("--timeout", type=float, default=2.0)
    s.set_defaults(func=cmd_status)

    s = sub.add_parser("sim", help="run the simulated deployment")
    s.add_argument("--manifest", type=Path, default=DEFAULT_MANIFEST)
    s.add_argument("--timeout", type=float, default=30.0)
    s.add_argument("--field", default=None, help="field to survey (default: the manifest's)")
    s.add_argument("--alive-only", action="store_true", help="only show the services alive")
    s.add_argument(
        "--new",
        action="store_true",
        help="abort a survey left unfinished in the run folder (its log and scans stay) "
        "and start a new one; without it, the unfinished survey is resumed and followed",
    )
    s.add_argument("--survey-timeout", type=float, default=900.0, metavar="S")
    s.add_argument("--register-timeout", type=float, default=600.0, metavar="S")
    s.set_defaults(func=cmd_sim)

    # Commands with heavy imports (OR-Tools, numba, Open3D, matplotlib): only the one
    # asked for is imported, so `phenorover status` or `certs` starts in a fraction of
    # a second rather than three.
    chosen = _command(argv)
    for name, (module, helptext) in LAZY.items():
        s = sub.add_parser(name, help=helptext)
        if name == chosen:
            importlib.import_module(module).add_command(s)

    args = p.parse_args(argv)
    setup_logging(args.log_level)
    code: int = args.func(args)
    return code


if __name__ == "__main__":
    sys.exit(main())
