"""Registration's options: the manifest's ``[services.register]`` section, read by
``phenorover register`` and by the registration the mission service starts at the end
of a survey (it passes its manifest on), so both register alike.

Where they come from, each over the one before: the defaults, the manifest's
``[services.register]`` (``--manifest``), a TOML file holding just that section
(``--config``, which replaces the manifest's), ``--set key=value`` overrides (TOML
values: ``--set register.refine.max_range=20``), and the flags ``--laz-voxel`` and
``--figures``/``--no-figures``. Registration is a job, not a process the launcher
keeps running: ``services.JOBS`` names the section so a manifest holding it is
validated like a service's.
"""

from __future__ import annotations

import argparse
from typing import Annotated

import msgspec

from common.config import Manifest
from services.register.pipeline import RegisterConfig

NAME = "register"


class RegisterRunConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """``[services.register]``: ``register`` (:class:`.pipeline.RegisterConfig`: C2C
    refinement, sphere detection, the target-based reference), ``laz_voxel`` (the
    merged LAZ's voxel, m; 0 keeps every point) and ``figures`` (write the PNGs).
    Where the scanner and antennas sit is the robot description's (``--robot``)."""

    register: RegisterConfig = RegisterConfig()
    laz_voxel: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 0.01
    figures: bool = True


def add_config_arguments(p: argparse.ArgumentParser) -> None:
    """The flags that choose the options (see the module docstring)."""
    from common.service_args import add_job_arguments

    add_job_arguments(p, NAME, "the PNG figures")
    p.add_argument("--laz-voxel", type=float, default=None, metavar="M", help="default 0.01")


def resolve(args: argparse.Namespace) -> tuple[RegisterRunConfig, Manifest | None]:
    """The effective options and the manifest (None without ``--manifest``) from the
    flags of :func:`add_config_arguments`. Raises ConfigError, one line naming the
    file and the key."""
    from common.service_args import resolve_config

    overrides = list(args.set)
    if args.laz_voxel is not None:
        overrides.append(f"laz_voxel={args.laz_voxel!r}")
    if args.figures is not None:
        overrides.append(f"figures={str(args.figures).lower()}")
    ns = argparse.Namespace(manifest=args.manifest, config=args.config, set=overrides)
    return resolve_config(NAME, RegisterRunConfig, ns)
