"""The traits job's options: the manifest's ``[services.traits]`` section, read by
``phenorover traits`` and by the traits job the mission service may start after
registration, so both measure alike.

Where they come from, each over the one before (as for ``phenorover register``): the
defaults, the manifest's ``[services.traits]`` (``--manifest``), a TOML file holding
just that section (``--config``, which replaces the manifest's), ``--set key=value``
overrides (TOML values: ``--set definition.cell=0.1``, ``--set ground.rigidness=2``)
and ``--figures``/``--no-figures``. What each trait is stays
:class:`common.canopy.CanopyDefinition`'s; only its parameters are set here.
"""

from __future__ import annotations

import argparse
from typing import Annotated

import msgspec

from common.canopy import CanopyDefinition
from common.config import Manifest

NAME = "traits"

Metres = Annotated[float, msgspec.Meta(gt=0.0, le=10.0)]


class GroundConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """How the ground is found (:mod:`.ground`), metres.

    The cloth simulation filter (Zhang et al. 2016, Remote Sens. 8:501) runs on the
    lowest point of every ``reduce_cell`` square, which keeps the ground and drops most
    of the canopy before the filter sees it (seconds instead of minutes on a survey).
    The ground model is the median of the ground points in ``grid_cell`` squares, holes
    filled from the nearest measured square."""

    reduce_cell: Annotated[float, msgspec.Meta(ge=0.01, le=1.0)] = 0.08
    """The squares whose lowest point the cloth filter runs on."""
    cloth_resolution: Annotated[float, msgspec.Meta(ge=0.05, le=5.0)] = 0.3
    """The cloth filter's resolution."""
    rigidness: Annotated[int, msgspec.Meta(ge=1, le=3)] = 3
    """The cloth's rigidness: 1 steep, 2 relief, 3 flat (a breeding field is flat, and a
    stiff cloth bridges a plot's canopy instead of sagging into it)."""
    class_threshold: Annotated[float, msgspec.Meta(gt=0.0, le=2.0)] = 0.1
    """How far above the cloth a point is still ground."""
    slope_smooth: bool = True
    """The cloth filter's slope smoothing."""
    iterations: Annotated[int, msgspec.Meta(ge=10, le=5000)] = 500
    """The cloth filter's iterations."""
    grid_cell: Annotated[float, msgspec.Meta(ge=0.05, le=5.0)] = 0.25
    """The ground model's squares."""
    crop_margin: Annotated[float, msgspec.Meta(ge=0.0, le=100.0)] = 1.0
    """How far beyond the field boundary points are kept (the scanner sees tens of
    metres past it, traits need none)."""
    max_step: Metres = 0.15
    """A ground square more than this above the median of the squares within
    ``step_window`` is canopy the filter let through, dropped and refilled."""
    step_window: Metres = 3.0
    """The neighbourhood ``max_step`` is judged over."""
    refine_band: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 0.03
    """The ground model is then made again from every point of the cloud within this of
    it (0: no second pass), since the lowest points the filter saw lie below the surface
    by the range noise (about 1 cm at 1 cm noise); keep it under
    ``definition.min_height`` so no canopy enters."""


class TraitsConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """``[services.traits]``: the per-plot traits of a registered survey, and of a season
    of them (:mod:`.series`)."""

    definition: CanopyDefinition = CanopyDefinition()
    """The traits' parameters (:class:`common.canopy.CanopyDefinition`)."""
    ground: GroundConfig = GroundConfig()
    """How the ground is found."""
    min_seen: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 0.5
    """A plot seen from both lanes over less than this share of its length (its ``seen``
    trait, :mod:`common.canopy`) is flagged ``occluded``: its traits describe only the
    part the scanner saw."""
    figures: bool = True
    """Write ``fieldmap.png`` (and a season's ``growth.png``)."""
    stable_margin: Annotated[float, msgspec.Meta(ge=0.0, le=5.0)] = 0.3
    """A season: how far from every plot a ground cell must be to count as stable
    (lanes, headlands: m)."""
    offset_tolerance_m: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 0.01
    """A season: the vertical offset between two dates' stable ground above which
    heights are corrected by it (1 cm: smaller ones are within what registration
    achieves)."""


def add_config_arguments(p: argparse.ArgumentParser) -> None:
    """The flags that choose the options (see the module docstring)."""
    from common.service_args import add_job_arguments

    add_job_arguments(p, NAME, "fieldmap.png")


def resolve(args: argparse.Namespace) -> tuple[TraitsConfig, Manifest | None]:
    """The effective options and the manifest (None without ``--manifest``) from the
    flags of :func:`add_config_arguments`. Raises ConfigError, one line naming the
    file and the key."""
    from common.service_args import resolve_job

    return resolve_job(NAME, TraitsConfig, args)
