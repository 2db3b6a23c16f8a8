"""What shapes the simulated world (:class:`services.sim.world.World`): the manifest's
``[services.sim.world]`` and its nested tables, the registration spheres (placed by
:mod:`services.sim.targets`), obstacles and soil among them."""

from __future__ import annotations

from typing import Annotated

import msgspec

from common.messages.core import Coordinate, NonNegative, Positive, Seed
from services.sim import lidar as lidar_mod
from services.sim.plant_config import FoliageConfig, TrialConfig
from services.sim.render import FaroNoise
from services.sim.robot import RobotConfig
from services.sim.terrain import TerrainConfig

Soil = Annotated[float, msgspec.Meta(ge=0, le=10)]


class TargetConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Sphere targets (metres, degrees), placed as :mod:`services.sim.targets` says
    when no sites are given."""

    count: Annotated[int, msgspec.Meta(ge=0, le=50)] = 5
    """How many spheres are placed when ``sites`` is none."""
    sites: list[tuple[Coordinate, Coordinate, NonNegative]] | None = None
    """Explicit ``[x, y, pole_height]`` per target in the ``field`` frame; none: ``count``
    sites are chosen for the scan locations."""
    scan_sites: list[tuple[Coordinate, Coordinate]] | None = None
    """The scan locations (``[x, y]``) the sites are chosen for; none: the field's
    candidate scan locations."""
    radius: Annotated[float, msgspec.Meta(gt=0, le=1)] = 0.1
    """The spheres' radius (m): Koppa target spheres, 200 mm diameter (the paper)."""
    pole_radius: Annotated[float, msgspec.Meta(gt=0, le=0.2)] = 0.01
    """The poles' radius (m): not stated in the paper; 20 mm is a common rod for sphere
    adapters."""
    pole_min: Annotated[float, msgspec.Meta(gt=0, le=5)] = 1.4
    """The shortest pole (m; the paper's 1.4-2 m)."""
    pole_max: Annotated[float, msgspec.Meta(gt=0, le=5)] = 2.0
    """The tallest pole (m)."""
    clearance: Annotated[float, msgspec.Meta(ge=0, le=5)] = 0.15
    """A sphere's horizontal clearance from any plot (m)."""
    lane_clearance: Annotated[float, msgspec.Meta(ge=0, le=5)] = 0.55
    """A site's clearance from the robot's paths (m): half the Husky's 0.67 m width,
    the sphere's radius and about 10 cm for cross-track error; beyond the lidar stop
    box's 0.30 m."""
    stop_clearance: Annotated[float, msgspec.Meta(ge=0, le=5)] = 1.0
    """A site's clearance from a scan location or the tour's origin (m), where the robot
    turns in place (0.6 m half-diagonal) and creeps during fine positioning."""
    min_points: Positive = 10.0
    """Expected points on a sphere for it to count as seen by a scan: a known-radius
    fit of 10 points at 0.3-0.5 mm noise is good to about 1 mm."""
    step_deg: Annotated[float, msgspec.Meta(gt=0, le=10)] = 0.36
    """The scan step the placement plans for (deg; the paper's)."""
    max_range: Positive = 15.0
    """The largest range a sphere is tried at (m)."""
    min_separation: NonNegative = 3.0
    """Spheres closer than this (m) would be confused by the matcher."""
    grid: Annotated[float, msgspec.Meta(gt=0.01, le=5)] = 0.2
    """The spacing of the candidate sites tried (m)."""


class BoxObstacle(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True, tag="box"):
    """An axis-aligned box standing on the ground (m)."""

    x: Coordinate
    """Its centre's x in the ``field`` frame."""
    y: Coordinate
    """Its centre's y."""
    size_x: Positive
    """Its size along x."""
    size_y: Positive
    """Its size along y."""
    height: Positive
    """Its height above the ground."""


class CylinderObstacle(
    msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True, tag="cylinder"
):
    """A vertical cylinder standing on the ground (a person's leg, a post) (m)."""

    x: Coordinate
    """Its axis' x in the ``field`` frame."""
    y: Coordinate
    """Its axis' y."""
    radius: Positive
    """Its radius."""
    height: Positive
    """Its height above the ground."""


Obstacle = BoxObstacle | CylinderObstacle


class SoilZone(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """A rectangle of the field frame (m) with a soil of its own (the paper's southern
    paths: loose rocks)."""

    x_min: Coordinate
    """Its lower x."""
    y_min: Coordinate
    """Its lower y."""
    x_max: Coordinate
    """Its upper x."""
    y_max: Coordinate
    """Its upper y."""
    soil: Soil
    """Its traction factor for wheel slip, as the world's ``soil``."""


class WorldConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Everything that shapes the world. Where the robot's sensors sit is the robot
    description's, not the world's."""

    seed: Seed = 0
    """Seeds terrain, plants and target heights (sensor noise takes the caller's
    generator)."""
    terrain: TerrainConfig = TerrainConfig()
    """The ground's shape."""
    foliage: FoliageConfig = FoliageConfig()
    """The plants' canopy generator."""
    targets: TargetConfig = TargetConfig()
    """The registration spheres."""
    obstacles: list[Obstacle] = []
    """Boxes (``type = "box"``) and cylinders (``type = "cylinder"``) standing in the
    field."""
    soil: Soil = 1.0
    """The whole field's traction factor for wheel slip: 1 firm, 2-3 loose or rocky."""
    soil_zones: list[SoilZone] = []
    """Rectangles with a soil of their own."""
    robot: RobotConfig = RobotConfig()
    """The simulated drivetrain."""
    scanner_noise: FaroNoise = FaroNoise()
    """The FARO's ranging and angular noise."""
    lidar: lidar_mod.LidarConfig = lidar_mod.LidarConfig()
    """The 2D lidar's model."""
    trial: TrialConfig = TrialConfig()
    """How the plots vary and the survey date."""
