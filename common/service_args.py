"""A service's command line and configuration, resolved before anything starts
(:func:`parse`): its flags (``--manifest``, ``--config``, ``--set key=value``,
``--dump-config``, where to connect, which clock), its config section from the
manifest with the overrides applied, and its robot description. A bad one is one
line and exit status 2, before any Zenoh session opens."""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import signal
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Generic, Protocol, TypeVar

import msgspec

from common.config import (
    ConfigError,
    Manifest,
    apply_overrides,
    decode_section,
    dump_toml,
    load_manifest,
    read_toml,
)
from common.robot import Robot, load_robot

C = TypeVar("C", bound=msgspec.Struct)

EXIT_CONFIG = 2
SERVICE_DOC = "A phenorover service: its config from a deploy manifest, on one Zenoh session."


class CliOptions(Protocol):
    """A service's own command-line flags: added to the common parser, then turned into
    ``key=value`` config overrides applied after the manifest and ``--set``."""

    def add(self, parser: argparse.ArgumentParser) -> None: ...

    def overrides(self, args: argparse.Namespace) -> list[str]: ...


def setup_logging(level: str) -> None:
    logging.basicConfig(
        level=level.upper(),
        format="%(asctime)s.%(msecs)03d %(levelname).1s %(name)s: %(message)s",
        datefmt="%H:%M:%S",
        stream=sys.stderr,
        force=True,
    )


def run_tool(
    name: str,
    doc: str | None,
    add_arguments: Callable[[argparse.ArgumentParser], None],
    command: Callable[[argparse.Namespace], int],
    argv: list[str] | None = None,
) -> int:
    """``python -m services.NAME`` of a one-shot tool (register, traits): its flags and
    ``--log-level``, logging set up, then ``command``'s exit status."""
    p = argparse.ArgumentParser(prog=f"python -m services.{name}", description=doc)
    add_arguments(p)
    p.add_argument("--log-level", default="info")
    args = p.parse_args(argv)
    setup_logging(args.log_level)
    # SIGTERM (the mission service stopping) unwinds normally, so no partial file stays
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    return command(args)


def parser(name: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=f"python -m services.{name}", description=SERVICE_DOC)
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
    options: ``--manifest``, ``--config``, ``--set`` (read by :func:`resolve_job`)
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
    name: str,
    config_type: type[C],
    manifest_path: str | Path | None,
    config: Path | None,
    overrides: Sequence[str],
) -> tuple[C, Manifest | None]:
    """``name``'s options: its manifest section (or the ``config`` file instead), with
    ``key=value`` ``overrides`` applied; and the manifest. Raises ConfigError."""
    manifest = load_manifest(manifest_path) if manifest_path else None
    section: dict[str, Any] = {}
    where = name
    if manifest is not None:
        section = manifest.services.get(name, {})
        where = f"{manifest_path}: [services.{name}]"
    if config is not None:
        section = read_toml(config)
        where = str(config)
    section = apply_overrides(section, list(overrides))
    return decode_section(section, config_type, where), manifest


def resolve_job(
    name: str, config_type: type[C], args: argparse.Namespace, extra: Sequence[str] = ()
) -> tuple[C, Manifest | None]:
    """A job's options and manifest from the flags of :func:`add_job_arguments`;
    ``extra``: the ``key=value`` overrides of the job's own flags, applied after
    ``--set``. Raises ConfigError, one line naming the file and the key."""
    overrides = [*args.set, *extra]
    if args.figures is not None:
        overrides.append(f"figures={str(args.figures).lower()}")
    return resolve_config(name, config_type, args.manifest, args.config, overrides)


@dataclasses.dataclass(frozen=True)
class Launch(Generic[C]):
    """What a service starts from: its name and config, the manifest it came from
    (``manifest_path``; None: none) and robot, and where and how it runs."""

    name: str
    cfg: C
    manifest: Manifest | None
    manifest_path: Path | None
    robot: Robot
    machine: str
    clock: str
    listen: list[str]
    connect: list[str]
    run_dir: Path
    field: str


def parse(
    name: str,
    config_type: type[C],
    argv: Sequence[str] | None = None,
    options: CliOptions | None = None,
) -> Launch[C] | int:
    """The service's launch from its command line, or the exit status when there is
    nothing to run (a config error, said in one line; ``--dump-config``)."""
    p = parser(name)
    if options is not None:
        options.add(p)
    args = p.parse_args(argv)
    setup_logging(args.log_level)
    try:
        if options is not None:
            args.set = [*args.set, *options.overrides(args)]
        cfg, manifest = resolve_config(name, config_type, args.manifest, args.config, args.set)
        # read before anything starts: a bad description is one line, not a traceback
        robot = load_robot(args.robot or (manifest.robot if manifest else ""))
    except ConfigError as exc:
        print(f"{name}: config error: {exc}", file=sys.stderr)
        return EXIT_CONFIG
    if args.dump_config:
        print(dump_toml(cfg), end="")
        return 0
    zs = manifest.zenoh if manifest else None
    return Launch(
        name=name,
        cfg=cfg,
        manifest=manifest,
        manifest_path=args.manifest,
        robot=robot,
        machine=args.machine or (manifest.machine if manifest else os.uname().nodename),
        clock=args.clock or (manifest.clock if manifest else "wall"),
        listen=args.listen or ["tcp/127.0.0.1:0"],
        connect=args.connect or (zs.local_endpoints() if zs else []),
        run_dir=Path(manifest.run_dir if manifest else "runs"),
        # no example field by default: a service that needs one and was given none fails
        field=args.field or (manifest.field if manifest else ""),
    )
