"""The one runner every service uses: ``run(name, Config, build)``.

It gives each service the same command line (``--manifest``, ``--config``,
``--set key=value``, ``--dump-config``), logging, SIGTERM/SIGINT -> stop, one Zenoh
session, a liveliness token (``alive/<machine>/<service>/<pid>/<since_ns>``), a
``health/<service>`` heartbeat and a ping RPC. The service itself is built by
``build(ctx, cfg)`` and only implements ``run(stop)``.
"""

from __future__ import annotations

import argparse
import dataclasses
import faulthandler
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Protocol, TypeVar

import msgspec
import zenoh

from common import keys
from common.clock import Clock
from common.config import (
    ConfigError,
    Manifest,
    apply_overrides,
    decode_section,
    dump_toml,
    load_manifest,
    read_toml,
    zenoh_config,
)
from common.field import FieldError
from common.lockstep import Inbox, LockstepClock
from common.messages.system import Health, Pong
from common.robot import Robot, default_robot, load_robot
from common.service_clock import Lockstep, service_clock
from common.transport import Bus

C = TypeVar("C", bound=msgspec.Struct)
log = logging.getLogger("phenorover")

EXIT_CONFIG = 2
EXIT_ZENOH = 3
# A service still running this long after SIGTERM/SIGINT writes every thread's stack
# to stderr (its log) and exits: the launcher SIGKILLs at 4 s, and a stack says where
# it hung where a kill says nothing.
STOP_DEADLINE_S = 3.5


class Service(Protocol):
    def run(self, stop: threading.Event) -> None:
        """Work until ``stop`` is set; return promptly after it is."""
        ...


class CliOptions(Protocol):
    """A service's own command-line flags: added to the common parser, then turned into
    ``key=value`` config overrides applied after the manifest and ``--set``."""

    def add(self, parser: argparse.ArgumentParser) -> None: ...

    def overrides(self, args: argparse.Namespace) -> list[str]: ...


@dataclasses.dataclass
class Context:
    """What a service gets from the runner. ``robot``: the deployment's robot
    description (the manifest's ``robot``), where every service finds the robot's
    geometry and limits."""

    name: str
    machine: str
    bus: Bus
    clock: Clock
    log: logging.Logger
    run_dir: Path
    field: str = "engr"
    robot: Robot = dataclasses.field(default_factory=default_robot)
    # the deployment manifest the service was started with (None: none), for the
    # child processes it starts, which read their own sections of it
    manifest: Path | None = None
    # the simulator's, in lockstep: the messages held until a step expects them
    inbox: Inbox | None = None


def setup_logging(level: str) -> None:
    logging.basicConfig(
        level=level.upper(),
        format="%(asctime)s.%(msecs)03d %(levelname).1s %(name)s: %(message)s",
        datefmt="%H:%M:%S",
        stream=sys.stderr,
        force=True,
    )


def _parser(name: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=f"python -m services.{name}", description=__doc__)
    p.add_argument("--manifest", type=Path, help="deploy manifest; uses [services.NAME]")
    p.add_argument("--config", type=Path, help="a TOML file holding just this service's config")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument("--dump-config", action="store_true", help="print the effective config")
    p.add_argument("--connect", action="append", default=[], metavar="ENDPOINT")
    p.add_argument("--listen", action="append", default=[], metavar="ENDPOINT")
    p.add_argument("--machine", default=None)
    p.add_argument("--clock", choices=["wall", "sim"], default=None)
    p.add_argument("--field", default=None, help="field surveyed (example name or file)")
    p.add_argument("--robot", default=None, help="robot description (shipped name or file)")
    p.add_argument("--log-level", default=os.environ.get("PHENOROVER_LOG", "info"))
    return p


def add_job_arguments(p: argparse.ArgumentParser, name: str, figures: str) -> None:
    """The flags by which a job (``[services.<name>]``, run on demand) takes its
    options: ``--manifest``, ``--config``, ``--set`` (read by :func:`resolve_config`)
    and ``--figures/--no-figures`` (``figures`` says what it writes)."""
    p.add_argument(
        "--manifest", type=Path, default=None, help=f"deploy manifest; uses [services.{name}]"
    )
    p.add_argument(
        "--config",
        type=Path,
        default=None,
        help=f"a TOML file holding just the [services.{name}] section (replaces the manifest's)",
    )
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override")
    p.add_argument(
        "--figures",
        action=argparse.BooleanOptionalAction,
        default=None,
        help=f"write {figures} (default: yes)",
    )


def resolve_config(
    name: str, config_type: type[C], args: argparse.Namespace
) -> tuple[C, Manifest | None]:
    manifest = load_manifest(args.manifest) if args.manifest else None
    section: dict[str, Any] = {}
    where = name
    if manifest is not None:
        section = manifest.services.get(name, {})
        where = f"{args.manifest}: [services.{name}]"
    if args.config is not None:
        section = read_toml(args.config)
        where = str(args.config)
    section = apply_overrides(section, args.set)
    return decode_section(section, config_type, where), manifest


def main(
    name: str,
    config_type: type[C],
    build: Callable[[Context, C], Service],
    argv: Sequence[str] | None = None,
    options: CliOptions | None = None,
    lockstep: Lockstep = "participant",
) -> int:
    parser = _parser(name)
    if options is not None:
        options.add(parser)
    args = parser.parse_args(argv)
    setup_logging(args.log_level)
    try:
        if options is not None:
            args.set = [*args.set, *options.overrides(args)]
        cfg, manifest = resolve_config(name, config_type, args)
        # read before anything starts: a bad description is one line, not a traceback
        robot = load_robot(args.robot or (manifest.robot if manifest else ""))
    except ConfigError as exc:
        print(f"{name}: config error: {exc}", file=sys.stderr)
        return EXIT_CONFIG
    if args.dump_config:
        print(dump_toml(cfg), end="")
        return 0

    machine = args.machine or (manifest.machine if manifest else os.uname().nodename)
    clock_kind = args.clock or (manifest.clock if manifest else "wall")
    zs = manifest.zenoh if manifest else None
    connect = args.connect or (zs.local_endpoints() if zs else [])
    listen = args.listen or ["tcp/127.0.0.1:0"]
    stop = threading.Event()

    def on_signal(signum: int, _frame: object) -> None:
        log.info("%s: received %s, stopping", name, signal.Signals(signum).name)
        if not stop.is_set():
            faulthandler.dump_traceback_later(STOP_DEADLINE_S, exit=True)
        stop.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    zenoh.init_log_from_env_or("error")
    try:
        session = zenoh.open(zenoh_config("peer", listen, connect))
    except zenoh.ZError as exc:
        print(f"{name}: cannot open Zenoh session ({listen} -> {connect}): {exc}", file=sys.stderr)
        return EXIT_ZENOH

    bus = Bus(session, name, namespace=manifest.namespace if manifest else "")
    in_step = clock_kind == "sim" and manifest is not None and manifest.lockstep
    clock, inbox = service_clock(bus, lockstep if in_step else "observer", clock_kind, manifest)
    since_ns = time.time_ns()
    run_dir = Path(manifest.run_dir if manifest else "runs")
    # no example field by default: a service that needs one and was given none fails
    field = args.field or (manifest.field if manifest else "")
    ctx = Context(
        name,
        machine,
        bus,
        clock,
        logging.getLogger(name),
        run_dir,
        field,
        robot,
        args.manifest,
        inbox if lockstep == "world" else None,
    )
    bus.serve(keys.PING.at(service=name), lambda p: Pong(service=name, text=p.text))
    health = threading.Thread(
        target=_heartbeat, args=(bus, name, machine, since_ns, stop), daemon=True
    )
    health.start()
    code = 0
    token: zenoh.LivelinessToken | None = None
    step_token: zenoh.LivelinessToken | None = None
    try:
        service = build(ctx, cfg)
        # alive only once it serves: build() has declared every subscriber and
        # queryable, so a supervisor that sees the token can talk to it at once
        token = session.liveliness().declare_token(
            keys.ALIVE.format(machine=machine, service=name, pid=os.getpid(), since_ns=since_ns)
        )
        if isinstance(clock, LockstepClock):  # the world waits for it from now on
            step_token = session.liveliness().declare_token(
                keys.LOCKSTEP.format(service=bus.participant)
            )
        log.info("%s: up on %s (%s clock), config: %s", name, machine, clock_kind, cfg)
        service.run(stop)
    except (ConfigError, FieldError) as exc:
        print(f"{name}: config error: {exc}", file=sys.stderr)
        code = EXIT_CONFIG
    except Exception:
        log.exception("%s: failed", name)
        code = 1
    finally:
        stop.set()
        health.join(timeout=2.0)
        if token is not None:
            token.undeclare()
        if step_token is not None:
            step_token.undeclare()
        if isinstance(clock, LockstepClock):
            clock.close()
        bus.close()
        session.close()
    log.info("%s: stopped", name)
    return code


def _heartbeat(bus: Bus, name: str, machine: str, since_ns: int, stop: threading.Event) -> None:
    pub = bus.publisher(keys.HEALTH.at(service=name), in_step=False)
    while True:
        pub.put(
            Health(
                stamp_ns=time.time_ns(),
                service=name,
                machine=machine,
                pid=os.getpid(),
                # a wall clock stepped back (NTP) must not make the heartbeat undecodable
                uptime_s=max(0.0, (time.time_ns() - since_ns) / 1e9),
                decode_errors=bus.decode_stats.total,
                last_error=bus.last_error,
                callback_errors=bus.callback_stats.total,
                counters=bus.reports(),
            )
        )
        if stop.wait(1.0):
            return


def run(
    name: str,
    config_type: type[C],
    build: Callable[[Context, C], Service],
    options: CliOptions | None = None,
    lockstep: Lockstep = "participant",
) -> None:
    """Entry point for ``services/<name>/__main__.py``; exits the process. In a
    simulated deployment in lockstep (the manifest's ``lockstep``) the service is a
    ``participant`` the world waits for, an ``observer`` it does not (the dashboard),
    or the ``world`` itself."""
    sys.exit(main(name, config_type, build, options=options, lockstep=lockstep))
