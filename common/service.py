"""The one runner every service uses: ``run(name, Config, build)``.

It gives each service the same command line (``--manifest``, ``--config``,
``--set key=value``, ``--dump-config``), logging, SIGTERM/SIGINT -> stop, one Zenoh
session, a liveliness token (``alive/<machine>/<service>/<pid>/<since_ns>``), a
``health/<service>`` heartbeat, a ping RPC and one answering with its resolved
configuration (``rpc/<service>/config``). The service itself is built by
``build(ctx, cfg)`` and only implements ``run(stop)``. The command line and the
config are resolved first (:mod:`common.service_args`), then the service is served
(:func:`serve`).
"""

from __future__ import annotations

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
from typing import Protocol, TypeVar

import msgspec
import zenoh

from common import keys
from common.clock import Clock
from common.config import ConfigError, dump_toml, zenoh_config
from common.field import FieldError
from common.lockstep import LockstepClock
from common.mailbox import Inbox
from common.messages.system import Health, Pong, ServiceConfig
from common.robot import Robot, default_robot
from common.service_args import EXIT_CONFIG, CliOptions, Launch, parse
from common.service_clock import Lockstep, service_clock
from common.transport import Bus

C = TypeVar("C", bound=msgspec.Struct)
log = logging.getLogger("phenorover")

EXIT_ZENOH = 3
# A service still running this long after SIGTERM/SIGINT writes every thread's stack
# to stderr (its log) and exits: the launcher SIGKILLs at 4 s, and a stack says where
# it hung where a kill says nothing.
STOP_DEADLINE_S = 3.5


class Service(Protocol):
    def run(self, stop: threading.Event) -> None:
        """Work until ``stop`` is set; return promptly after it is."""
        ...


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


def main(
    name: str,
    config_type: type[C],
    build: Callable[[Context, C], Service],
    argv: Sequence[str] | None = None,
    options: CliOptions | None = None,
    lockstep: Lockstep = "participant",
) -> int:
    """Parse the command line and run the service (:func:`serve`); its exit status."""
    got = parse(name, config_type, argv, options)
    if isinstance(got, int):
        return got
    return serve(got, build, lockstep)


def serve(launch: Launch[C], build: Callable[[Context, C], Service], lockstep: Lockstep) -> int:
    """Open the Zenoh session, build the service and run it until a signal stops it;
    its exit status."""
    name, manifest = launch.name, launch.manifest
    stop = _stop_on_signals(name)
    zenoh.init_log_from_env_or("error")
    try:
        session = zenoh.open(zenoh_config("peer", launch.listen, launch.connect))
    except zenoh.ZError as exc:
        print(
            f"{name}: cannot open Zenoh session ({launch.listen} -> {launch.connect}): {exc}",
            file=sys.stderr,
        )
        return EXIT_ZENOH
    bus = Bus(session, name, namespace=manifest.namespace if manifest else "")
    in_step = launch.clock == "sim" and manifest is not None and manifest.lockstep
    clock, inbox = service_clock(bus, lockstep if in_step else "observer", launch.clock, manifest)
    since_ns = time.time_ns()
    ctx = Context(
        name,
        launch.machine,
        bus,
        clock,
        logging.getLogger(name),
        launch.run_dir,
        launch.field,
        launch.robot,
        launch.manifest_path,
        inbox if lockstep == "world" else None,
    )
    # constant answers, so never held for a step: the mission asks every service's
    # configuration (its own too) from within a handler that holds its step
    bus.serve(keys.PING.at(service=name), lambda p: Pong(service=name, text=p.text), stepped=False)
    resolved = ServiceConfig(service=name, machine=launch.machine, toml=dump_toml(launch.cfg))
    bus.serve(keys.CONFIG.at(service=name), lambda _: resolved, stepped=False)
    health = threading.Thread(
        target=_heartbeat, args=(bus, name, launch.machine, since_ns, stop), daemon=True
    )
    health.start()
    tokens: list[zenoh.LivelinessToken] = []
    code = 0
    try:
        service = build(ctx, launch.cfg)
        # alive only once it serves: build() has declared every subscriber and
        # queryable, so a supervisor that sees the token can talk to it at once
        alive = keys.ALIVE.format(
            machine=launch.machine, service=name, pid=os.getpid(), since_ns=since_ns
        )
        tokens.append(session.liveliness().declare_token(alive))
        if isinstance(clock, LockstepClock):  # the world waits for it from now on
            step = keys.LOCKSTEP.format(service=bus.participant)
            tokens.append(session.liveliness().declare_token(step))
        log.info(
            "%s: up on %s (%s clock), config: %s", name, launch.machine, launch.clock, launch.cfg
        )
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
        for token in tokens:
            token.undeclare()
        if isinstance(clock, LockstepClock):
            clock.close()
        bus.close()
        session.close()
    log.info("%s: stopped", name)
    return code


def _stop_on_signals(name: str) -> threading.Event:
    """An event SIGTERM and SIGINT set; a service still running ``STOP_DEADLINE_S``
    after the first writes every thread's stack and exits."""
    stop = threading.Event()

    def on_signal(signum: int, _frame: object) -> None:
        log.info("%s: received %s, stopping", name, signal.Signals(signum).name)
        if not stop.is_set():
            faulthandler.dump_traceback_later(STOP_DEADLINE_S, exit=True)
        stop.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    return stop


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
