"""The ``phenorover`` command: run deployments, ask who is alive, run the simulation."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import zenoh

from common.config import ConfigError, load_manifest, zenoh_config
from common.service import setup_logging
from common.status import Alive, format_table, query_alive

REPO = Path(__file__).resolve().parent.parent
DEFAULT_MANIFEST = REPO / "deploy" / "sim.toml"

log = logging.getLogger("phenorover")


def open_client(manifest: Path | None, connect: list[str]) -> zenoh.Session:
    """A client session to a machine's router: the CLI's way onto the network."""
    if not connect:
        m = load_manifest(manifest or DEFAULT_MANIFEST)
        connect = m.zenoh.local_endpoints()
    zenoh.init_log_from_env_or("error")
    return zenoh.open(zenoh_config("client", [], connect))


def wait_alive(
    session: zenoh.Session, services: set[str], timeout: float, machine: str | None = None
) -> list[Alive]:
    """Poll liveliness until every name in ``services`` is alive; returns what was seen."""
    deadline = time.monotonic() + timeout
    seen: list[Alive] = []
    while time.monotonic() < deadline:
        seen = query_alive(session, timeout=1.0)
        names = {a.service for a in seen if machine is None or a.machine == machine}
        if services <= names:
            return seen
        time.sleep(0.2)
    return seen


def cmd_up(args: argparse.Namespace) -> int:
    from common.launcher import up

    return up(args.manifest)


def cmd_status(args: argparse.Namespace) -> int:
    try:
        session = open_client(args.manifest, args.connect)
    except (ConfigError, zenoh.ZError) as exc:
        print(f"phenorover status: {exc}", file=sys.stderr)
        return 2
    with session:
        entries = query_alive(session, timeout=args.timeout)
    print(format_table(entries) if entries else "no phenorover service is alive")
    return 0 if entries else 1


def cmd_sim(args: argparse.Namespace) -> int:
    """The simulated deployment: all services alive, then (unless --alive-only) a
    whole survey of the field, with a line per step and a summary."""
    from common.launcher import Launcher
    from common.transport import Bus
    from services.mission.cli import describe, run_survey

    try:
        launcher = Launcher(args.manifest)
    except ConfigError as exc:
        print(f"phenorover sim: {exc}", file=sys.stderr)
        return 2
    wanted = set(launcher.manifest.services)
    t0 = time.monotonic()
    with launcher, open_client(args.manifest, []) as session:
        seen = wait_alive(session, wanted, timeout=args.timeout)
        missing = wanted - {a.service for a in seen}
        print(format_table(seen), flush=True)
        if missing:
            print(f"phenorover sim: not alive after {args.timeout:g} s: {sorted(missing)}")
            return 1
        print(f"all {len(wanted)} services alive after {time.monotonic() - t0:.1f} s")
        if args.alive_only:
            return 0
        bus = Bus(session, "sim-cli")
        try:
            final = run_survey(bus, args.field or launcher.manifest.field, args.survey_timeout)
            if final is not None:
                from services.register.hook import wait_registration

                final = wait_registration(bus, final, args.register_timeout)
        finally:
            bus.close()
        wall = time.monotonic() - t0
        if final is None:
            return 1
        print(
            f"summary: {describe(final)}; wall {wall:.0f} s; files in "
            f"{Path(launcher.manifest.run_dir) / final.mission}"
        )
        return 0 if final.phase.value == "done" else 1


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="phenorover", description=__doc__)
    p.add_argument("--log-level", default="info")
    sub = p.add_subparsers(dest="cmd", required=True)

    s = sub.add_parser("up", help="run the services of a manifest on this machine")
    s.add_argument("manifest", type=Path)
    s.set_defaults(func=cmd_up)

    s = sub.add_parser("status", help="which services are alive, where, since when")
    s.add_argument("--manifest", type=Path, default=None)
    s.add_argument("--connect", action="append", default=[], metavar="ENDPOINT")
    s.add_argument("--timeout", type=float, default=2.0)
    s.set_defaults(func=cmd_status)

    s = sub.add_parser("sim", help="run the simulated deployment")
    s.add_argument("--manifest", type=Path, default=DEFAULT_MANIFEST)
    s.add_argument("--timeout", type=float, default=30.0)
    s.add_argument("--field", default=None, help="field to survey (default: the manifest's)")
    s.add_argument("--alive-only", action="store_true", help="only show the services alive")
    s.add_argument("--survey-timeout", type=float, default=900.0, metavar="S")
    s.add_argument("--register-timeout", type=float, default=600.0, metavar="S")
    s.set_defaults(func=cmd_sim)

    from services.planner.cli import add_arguments, cmd_plan

    s = sub.add_parser("plan", help="plan scan locations and the route for a field")
    add_arguments(s)
    s.set_defaults(func=cmd_plan)

    from services.nav import navtest

    s = sub.add_parser("nav-test", help="run one of the paper's navigation experiments")
    navtest.add_arguments(s)
    s.set_defaults(func=navtest.run)

    from services.mission.cli import add_mission_arguments, cmd_mission

    s = sub.add_parser("mission", help="control the mission service")
    add_mission_arguments(s)
    s.set_defaults(func=cmd_mission)

    from services.register.cli import add_arguments as add_register_arguments
    from services.register.cli import cmd_register

    s = sub.add_parser("register", help="register a mission's scans and write its report")
    add_register_arguments(s)
    s.set_defaults(func=cmd_register)

    args = p.parse_args(argv)
    setup_logging(args.log_level)
    code: int = args.func(args)
    return code


if __name__ == "__main__":
    sys.exit(main())
