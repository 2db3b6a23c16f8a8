"""The simulated world: ground, plants, targets and obstacles of one field, and the
sensors that look at them. Pure computation: the sim service owns the clock and the
bus and calls into a :class:`World`. Everything is in the ``field`` frame (metres,
radians) and is the ground truth the evaluation scores against.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import msgspec
import numpy as np
import numpy.typing as npt

from common.arrays import F64, U8
from common.field import Field, FieldLayout
from common.geo import rot_zyx
from common.robot import Robot, default_robot
from services.sim import lidar as lidar_mod
from services.sim import robot as robot_mod
from services.sim.foliage import Foliage, build_foliage
from services.sim.render import Scan, ScanSettings, render
from services.sim.robot import RobotState
from services.sim.scene import OBSTACLE, PLOT, POLE, SPHERE, Scene
from services.sim.sky import SkyMask
from services.sim.targets import Survey, Targets, build_targets, drive_network
from services.sim.terrain import Terrain, build_terrain
from services.sim.trial import TrialPlan, plan_trial
from services.sim.truth_points import truth_points
from services.sim.world_config import BoxObstacle, Obstacle, WorldConfig


def _obstacle_arrays(obstacles: list[Obstacle], terrain: Terrain) -> tuple[F64, F64]:
    boxes, cyls = [], []
    for ob in obstacles:
        z = float(terrain.height(ob.x, ob.y))
        if isinstance(ob, BoxObstacle):
            hx, hy = ob.size_x / 2, ob.size_y / 2
            boxes.append(
                [ob.x - hx, ob.y - hy, z - 0.2, ob.x + hx, ob.y + hy, z + ob.height, OBSTACLE]
            )
        else:
            cyls.append([ob.x, ob.y, z - 0.2, z + ob.height, ob.radius, OBSTACLE])
    return np.array(boxes, dtype=np.float64).reshape(-1, 7), np.array(cyls).reshape(-1, 6)


class World:
    """Terrain, foliage, targets and obstacles of one field, built deterministically
    from ``(layout, field, cfg)``, and the ``robot`` in it (its description: where its
    antennas, scanner and lidar sit, its wheels and limits; default: the shipped one)."""

    def __init__(
        self,
        layout: FieldLayout,
        field: Field,
        cfg: WorldConfig | None = None,
        robot: Robot | None = None,
    ) -> None:
        self.layout, self.field = layout, field
        self.cfg = cfg = cfg or WorldConfig()
        self.robot = robot or default_robot()
        self.terrain: Terrain = build_terrain(field.bounds, cfg.terrain, cfg.seed)
        # the trial's plan (None: every plot the same plants, as ENGR and SPL are)
        self.trial: TrialPlan | None = plan_trial(layout, field, cfg.foliage, cfg.trial, cfg.seed)
        plans = None if self.trial is None else [p.growth for p in self.trial.plots]
        self.foliage: Foliage = build_foliage(
            field.plot_boxes, self.terrain, cfg.foliage, cfg.seed, plans
        )
        ob_boxes, ob_cyls = _obstacle_arrays(cfg.obstacles, self.terrain)
        self.targets: Targets = self._place_targets(ob_cyls, ob_boxes)
        n = len(self.targets.spheres)
        spheres = np.column_stack([self.targets.spheres, np.full(n, SPHERE)])
        cyls = np.vstack([np.column_stack([self.targets.poles, np.full(n, POLE)]), ob_cyls])
        self.scene = Scene(self.terrain, self.foliage, spheres, cyls, ob_boxes)
        # the 2D lidar sees plots as solid boxes reaching below the ground
        plots = field.plot_boxes.copy()
        plots[:, 2] = self.terrain.hmin - 0.5
        plots[:, 5] += self.terrain.hmax
        plot_boxes = np.column_stack([plots, np.full(len(plots), PLOT)])
        self._lidar_memo: tuple[bytes, F64] | None = None  # (pose, true ranges)
        self.lidar_scene = Scene(
            self.terrain, None, spheres, cyls, np.vstack([plot_boxes, ob_boxes])
        )
        # the GNSS antennas' sky: each plot's canopy top stands on the ground at its centre
        canopy = field.plot_boxes.copy()
        if self.trial is not None:  # a trial's crop is as tall as its tallest plant
            tallest = [
                float(p.growth.heights[p.growth.emerged].max(initial=0.0)) for p in self.trial.plots
            ]
            canopy[:, 5] = np.minimum(canopy[:, 5], canopy[:, 2] + np.array(tallest))
        centre = canopy[:, [0, 1]] / 2 + canopy[:, [3, 4]] / 2
        canopy[:, 5] += self.terrain.height(centre[:, 0], centre[:, 1])
        self.sky = SkyMask(canopy)

    def _place_targets(self, ob_cyls: F64, ob_boxes: F64) -> Targets:
        """The spheres: the manifest's sites, else chosen for its ``scan_sites``, else the
        field's (as the surveyor set them out), else chosen by the simulator for the
        lane crossings a survey can scan from, seen through the plants and obstacles (see
        :mod:`services.sim.targets`). The robot's own planner is never asked: the
        world must not move when the product does."""
        tc = self.cfg.targets
        if self._field_sites:
            tc = msgspec.structs.replace(tc, sites=[tuple(s) for s in self.layout.targets])
        if tc.sites is not None or tc.count == 0:
            return build_targets(self.field, self.terrain, tc, None, None)
        if tc.scan_sites is not None:
            xy = np.array(tc.scan_sites, dtype=np.float64).reshape(-1, 2)
        else:
            xy = self.field.cand_xy.reshape(-1, 2)
        paths = drive_network(self.field)
        origins = np.array(
            [
                self.scanner_pose(self.settle(RobotState(x=float(x), y=float(y), yaw=0.0)))[:3, 3]
                for x, y in xy
            ]
        ).reshape(-1, 3)
        stops = np.vstack([xy, self.field.origin_xy[None, :]])
        bare = Scene(self.terrain, self.foliage, np.zeros((0, 5)), ob_cyls, ob_boxes)
        survey = Survey(origins=origins, paths=paths, stops=stops)
        return build_targets(self.field, self.terrain, tc, bare, survey)

    @property
    def placement(self) -> str:
        """How the spheres were placed, for the logs and the world's description."""
        if self.cfg.targets.sites is not None:
            return "the manifest's [services.sim.world.targets] sites"
        if self.cfg.targets.count == 0:
            return "none"
        if self.cfg.targets.scan_sites is not None:
            return "chosen by the simulator for the manifest's scan_sites"
        if self._field_sites:
            return "the field file's target sites"
        return "chosen by the simulator for the field's candidate scan locations"

    @property
    def _field_sites(self) -> bool:
        tc = self.cfg.targets
        return (
            bool(self.layout.targets)
            and tc.count > 0
            and tc.sites is None
            and tc.scan_sites is None
        )

    @property
    def sphere_centres(self) -> F64:
        """Ground-truth sphere centres (S, 3), field frame (m)."""
        return self.targets.centres

    def settle(self, state: RobotState) -> RobotState:
        """``state`` placed on the ground (z, pitch, roll from the terrain)."""
        return robot_mod.settle(state, self.terrain, self.robot)

    def step_robot(
        self, state: RobotState, cmd_v: float, cmd_w: float, dt: float, rng: np.random.Generator
    ) -> RobotState:
        """Advance the robot under a commanded twist (see :func:`robot.step`)."""
        soil = self.soil_at(state.x, state.y)
        return robot_mod.step(
            state, cmd_v, cmd_w, dt, self.terrain, rng, self.cfg.robot, soil, self.robot
        )

    def soil_at(self, x: float, y: float) -> float:
        """The traction factor under (x, y): the last zone holding it, else the world's."""
        for z in reversed(self.cfg.soil_zones):
            if z.x_min <= x <= z.x_max and z.y_min <= y <= z.y_max:
                return z.soil
        return self.cfg.soil

    def encoder_twist(self, state: RobotState, rng: np.random.Generator) -> tuple[float, float]:
        """Wheel-odometry (v, w) of ``state`` (blind to slip, noisy)."""
        return robot_mod.encoder_twist(state, rng, self.cfg.robot)

    def gnss_truth(self, state: RobotState) -> F64:
        """True field-frame positions (2, 3) of the two GNSS antenna phase centres."""
        return robot_mod.body_to_field(state, np.array([a.xyz for a in self.robot.antennas]))

    def sky_blocked(self, antennas: F64) -> tuple[float, float]:
        """The share of each antenna's sky (``antennas``: (2, 3), field frame) the crop
        hides (:mod:`services.sim.sky`)."""
        return self.sky.blocked(antennas[0]), self.sky.blocked(antennas[1])

    def scanner_pose(self, state: RobotState) -> F64:
        """4x4 field <- scanner of the FARO on the robot at ``state`` (its zero azimuth
        turned by the mount's yaw from base_link x)."""
        mount = self.robot.scanner
        m = robot_mod.pose_matrix(state)
        m[:3, :3] = m[:3, :3] @ rot_zyx(0.0, 0.0, mount.yaw_rad)
        m[:3, 3] = robot_mod.body_to_field(state, np.array(mount.xyz))
        return m

    def render_scan(self, pose: F64, settings: ScanSettings, rng: np.random.Generator) -> Scan:
        """A FARO scan from the scanner pose ``pose`` (4x4, field <- scanner)."""
        return render(self.scene, pose, settings, rng, self.cfg.scanner_noise)

    def lidar_scan(
        self,
        state: RobotState,
        rng: np.random.Generator,
        transient: Sequence[Obstacle] = (),
    ) -> npt.NDArray[np.float32]:
        """A Hokuyo sweep from the robot at ``state`` (float32 m, inf = no return).
        ``transient``: obstacles standing there just now besides the world's own (an
        injected fault, see :mod:`services.sim.faults`); the same random numbers are
        drawn with or without them."""
        scene = self.lidar_scene
        pose = lidar_mod.lidar_pose(state, self.robot.lidar)
        if transient:
            boxes, cyls = _obstacle_arrays(list(transient), self.terrain)
            scene = dataclasses.replace(
                scene,
                boxes=np.vstack([scene.boxes, boxes]),
                cylinders=np.vstack([scene.cylinders, cyls]),
            )
            return lidar_mod.noisy(
                lidar_mod.true_ranges(scene, pose, self.cfg.lidar), self.cfg.lidar, rng
            )
        # a standing robot's lidar sees the same world from the same pose: cast once
        key = pose.tobytes()
        if self._lidar_memo is None or self._lidar_memo[0] != key:
            self._lidar_memo = (key, lidar_mod.true_ranges(scene, pose, self.cfg.lidar))
        return lidar_mod.noisy(self._lidar_memo[1], self.cfg.lidar, rng)

    def truth_points(self, spacing: float = 0.05) -> tuple[F64, U8]:
        """A dense, deterministic sample of every surface with labels, for scoring
        registrations cloud-to-truth (see :func:`services.sim.truth_points.truth_points`)."""
        return truth_points(self.field, self.terrain, self.foliage, self.targets, spacing)
