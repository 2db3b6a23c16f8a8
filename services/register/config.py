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
from common.messages.core import NonNegative, Positive, Seed
from services.register.spheres import SphereConfig
from services.register.targets import TargetConfig

NAME = "register"


class RefineConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Cloud-to-cloud refinement (``[register.refine]``; the steps:
    :mod:`services.register.refine`). The ``nav_sigma_*`` are the pose graph's prior:
    1 sigma of the navigation pose error the graph may correct."""

    voxel: Positive = 0.05
    """Every scan is voxel-downsampled to this before alignment (m)."""
    max_range: Positive = 30.0
    """Every scan is cropped to this distance from its scanner (m)."""
    neighbours: Annotated[int, msgspec.Meta(ge=5)] = 20
    """The neighbours a point's normal and local covariance come from."""
    max_pair_distance: Positive = 10.0
    """Scans whose navigation positions are within this of each other are aligned as a
    pair (m)."""
    coarse_correspondence: Positive = 0.3
    """GICP's first correspondence radius (m), the paper's 30 cm ("we limited the radius
    to search for common points to 30 cm"); a pair with fewer than ``min_overlap`` of
    its points within it at the navigation poses is refused before GICP."""
    fine_correspondence: Positive = 0.1
    """The correspondence radius of GICP's second pass (m), and that of a pair's overlap,
    residual and information after alignment."""
    max_iterations: Annotated[int, msgspec.Meta(ge=1)] = 100
    """GICP's iterations per pass, at most."""
    epsilon: Positive = 1e-5
    """GICP stops when a step is below this (rad, m): small_gicp's 0.1 deg / 1 mm
    defaults stop early on the weakly constrained along-lane direction."""
    view_angle_deg: Annotated[float, msgspec.Meta(gt=0, le=180)] = 45.0
    """Only points that both scanners see from within this of each other's view take
    part (deg), plus ground."""
    ground_normal_z: Annotated[float, msgspec.Meta(ge=0, le=1)] = 0.9
    """A point whose unit normal's vertical component is at least this is ground, which
    takes part from any view."""
    min_overlap: Annotated[float, msgspec.Meta(ge=0, le=1)] = 0.3
    """A pair is used only when this share of its source points finds a correspondence
    within ``fine_correspondence`` after alignment (low-overlap pairs across the plots
    converge to wrong minima in simulation)."""
    gate_sigma: Positive = 4.0
    """A pair is used only when each component of its correction stays within this many
    relative navigation sigmas (sqrt(2) nav sigmas)."""
    point_sigma: Positive = 0.01
    """The floor of the point-to-plane residual sigma that scales the pair information
    (m); the pair's own RMSE when larger."""
    independent_voxel: NonNegative = 0.5
    """The pair information counts one point per cube of this size (m; 0: every point),
    the field's cell size: residuals on plants are correlated over a plant, not
    independent per point, so a pair of 20 000 points is not trusted to a fraction of
    a millimetre and cannot override the navigation prior with its own bias."""
    nav_sigma_xy: Positive = 0.005
    """The navigation prior in x and y (m): what the scan's navigation pose is worth. Its
    position fixes the graph's rotation as well as its place (scans tens of metres
    apart, each placed to millimetres, hold the whole block's heading better than any
    one compass reading). Ours, the estimate at the scan's end after minutes of
    standing: 5 mm, of the order of the filter's own position SD there (the mission
    log's ``sd_x``, ``sd_y``). A filter that forgets while standing (the paper's)
    is worth about 2 cm, and its profile says so."""
    nav_sigma_z: Positive = 0.05
    """The navigation prior in z (m)."""
    nav_sigma_tilt_deg: Positive = 0.1
    """The navigation prior in roll and pitch (deg): the compensator's tilt."""
    nav_sigma_yaw_deg: Positive = 0.3
    """The navigation prior in heading (deg)."""
    threads: Annotated[int, msgspec.Meta(ge=1)] = 2
    """Scan pairs aligned at once, each in its own single-threaded process
    (:mod:`common.workers`: why not OpenMP threads); the poses do not depend on it."""
    use_targets: bool = True
    """Sphere centres seen by two or more scans join the pose graph (a user has the
    targets; the paper's C2C did without them); false: the paper's C2C alone."""
    target_sigma: Positive = 0.003
    """1 sigma of a fitted sphere centre in the pose graph (m)."""


class RegisterConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Everything :func:`services.register.pipeline.register` takes."""

    refine: RefineConfig = RefineConfig()
    """Cloud-to-cloud refinement of all scans jointly."""
    spheres: SphereConfig = SphereConfig()
    """Sphere detection in every scan."""
    targets: TargetConfig = TargetConfig()
    """The target-based reference."""
    sample_points: Annotated[int, msgspec.Meta(ge=1, le=10_000_000)] = 5000
    """Each scan's uniform subsample for the scan point statistics."""
    cloud_points: Annotated[int, msgspec.Meta(ge=1, le=10_000_000)] = 20000
    """Source points for the cloud-to-cloud distances."""
    overlap_radius: Annotated[float, msgspec.Meta(gt=0, le=1.0)] = 0.3
    """The overlap residuals' search radius of the scan point statistics (m): the paper's
    C2C searched 30 cm."""
    seed: Seed = 0
    """The seed of the subsamples and of the spheres' RANSAC."""


class RegisterRunConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """``[services.register]``. Where the scanner and antennas sit is the robot
    description's (``--robot``)."""

    register: RegisterConfig = RegisterConfig()
    """C2C refinement, sphere detection, the target-based reference."""
    laz_voxel: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 0.01
    """The merged LAZ's voxel (m); 0 keeps every point."""
    figures: bool = True
    """Write the PNG figures."""


def add_config_arguments(p: argparse.ArgumentParser) -> None:
    """The flags that choose the options (see the module docstring)."""
    from common.service_args import add_job_arguments

    add_job_arguments(p, NAME, "the PNG figures")
    p.add_argument("--laz-voxel", type=float, default=None, metavar="M", help="default 0.01")


def resolve(args: argparse.Namespace) -> tuple[RegisterRunConfig, Manifest | None]:
    """The effective options and the manifest (None without ``--manifest``) from the
    flags of :func:`add_config_arguments`. Raises ConfigError, one line naming the
    file and the key."""
    from common.service_args import resolve_job

    extra = [] if args.laz_voxel is None else [f"laz_voxel={args.laz_voxel!r}"]
    return resolve_job(NAME, RegisterRunConfig, args, extra)
