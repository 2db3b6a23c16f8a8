"""The nav service's Zenoh shell: localization from odometry, fixes, heading and the
IMU's tilt (calibrated by the scanner's compensator); route following from
``rpc/nav/cmd``; pose, progress and velocity commands out."""

from __future__ import annotations

import math
import threading

import numpy as np

from common import clock as clk
from common import keys
from common.field_geojson import load_georeferenced
from common.geo import rot_zyx
from common.messages.base import Imu, LaserScan, Odometry, Twist
from common.messages.core import BASE_FRAME, FIELD_FRAME
from common.messages.gnss import GnssHeading, NavSatFix
from common.messages.nav import (
    LEASE_ENDED,
    NavCommand,
    NavProgress,
    NavReply,
    NavState,
    PoseEstimate,
)
from common.messages.scan import ScannerState, ScannerStatus
from common.service import Context
from common.status import parse_token
from services.nav.config import Mounts, NavConfig, check_limits
from services.nav.ekf import Localizer
from services.nav.fine import pose_sds
from services.nav.follower import Follower
from services.nav.gyro import Gyro
from services.nav.obstacles import ObstacleWatch, hits_ahead, hits_on_leg
from services.nav.routes import Routes
from services.nav.tilt import Tilt, tilt_of


class NavService:
    def __init__(self, ctx: Context, cfg: NavConfig) -> None:
        self.ctx, self.cfg = ctx, cfg
        check_limits(cfg, ctx.robot)
        self.mounts = Mounts.of(ctx.robot)
        self.frame, fld = load_georeferenced(ctx.field, ctx.clock)
        g = cfg.obstacle_crop_margin_m
        self.crop = fld.plot_boxes[:, [0, 1, 3, 4]] + np.array([-g, -g, g, g])
        self.loc = Localizer(cfg.ekf)
        self.follower = Follower(cfg.follower)
        self.tilt = Tilt(cfg.tilt, ctx.robot.imu)
        self.gyro = Gyro(cfg.gyro)
        m = ctx.robot.imu
        # the unit's rates turned into base_link by its mounting
        self._imu_to_base = rot_zyx(m.roll_rad, m.pitch_rad, m.yaw_rad)
        self._still = False  # the last odometry was taken standing
        self._odom_at = 0.0  # when the last odometry arrived (s)
        self._scan: tuple[int, float] | None = None  # (scan id, when its scan was seen)
        self._lock = threading.Lock()
        self.routes = Routes(self.follower, self._lock, fld.bounds, cfg.route_margin_m, ctx)
        self.obstacles = ObstacleWatch(cfg.obstacle_min_points, cfg.obstacle_scans)
        self._moving_until = 0.0  # time of the last non-zero velocity command (s)
        self._last_fix = -math.inf  # time of the last fused fix (s)
        bus = ctx.bus
        self.pose_pub = bus.publisher(keys.NAV_POSE)
        self.progress_pub = bus.publisher(keys.NAV_PROGRESS)
        self.cmd_pub = bus.publisher(keys.BASE_CMD_VEL)
        bus.subscribe(keys.BASE_ODOM, self._on_odom)
        for antenna in (1, 2):
            bus.subscribe(keys.GNSS_FIX.at(antenna=antenna), self._on_fix)
        bus.subscribe(keys.GNSS_HEADING, self._on_heading)
        bus.subscribe(keys.BASE_SCAN, self._on_scan)
        bus.subscribe(keys.BASE_IMU, self._on_imu)
        bus.subscribe(keys.SCANNER_STATUS, self._on_scanner)
        bus.serve(keys.NAV_CMD, self.handle)
        self._missions: set[str] = set()  # liveliness tokens of mission supervisors
        bus.watch_alive(self._on_alive)
        c = self.loc.counters
        bus.report("ekf_rejected", lambda: c.rejected)
        bus.report("ekf_resets", lambda: c.resets)
        bus.report("imu_calibrations", lambda: self.tilt.calibrations)
        bus.report("imu_rejected", lambda: self.tilt.rejected)
        bus.report("imu_turn_levellings", lambda: self.tilt.turns.spots)
        bus.report("gyro_refused", lambda: self.gyro.refused)

    def _on_odom(self, m: Odometry) -> None:
        t = m.stamp_ns / 1e9
        with self._lock:
            # standing: nothing commanded for a while and the encoders agree (so a
            # robot pushed or driven by someone else is never taken to stand)
            still = (
                t - self._moving_until >= self.cfg.still_after_s
                and m.v * m.v <= 16.0 * max(m.var_v, 1e-12)
                and m.w * m.w <= 16.0 * max(m.var_w, 1e-12)
            )
            self._still = still
            # the wheels' yaw rate weighed against the gyro's while it has a fresh one
            now = self.ctx.clock.now_ns() / 1e9
            w, var_w = self.gyro.odometry_rate(now, m.w, m.var_w, now - self._odom_at)
            self._odom_at = now
            self.loc.update_odometry(t, m.v, w, m.var_v, var_w, still=still)
            self.tilt.motion(t, m.v, m.w)

    def _on_imu(self, m: Imu) -> None:
        # timed on arrival: an IMU sample says what the tilt is now, and a stamp from
        # the future must not keep a tilt fresh for ever
        t = self.ctx.clock.now_ns() / 1e9
        with self._lock:
            x = self.loc.x
            pose = (float(x[0]), float(x[1]), float(x[2])) if self.loc.localized() else None
            spots = self.tilt.turns.spots
            self.tilt.imu(t, m.roll, m.pitch, pose)
            wz = float((self._imu_to_base @ np.array([m.wx, m.wy, m.wz]))[2])
            self.gyro.sample(t, wz, self._still)
            if self.tilt.turns.spots > spots and not self.tilt.calibrations:
                b = self.tilt.bias
                self.ctx.log.info(
                    "IMU tilt levelled by a turn in place: bias roll %.3f, pitch %.3f deg "
                    "(%d turns)",
                    math.degrees(b[0]),
                    math.degrees(b[1]),
                    spots + 1,
                )

    def _on_scanner(self, m: ScannerStatus) -> None:
        """At the end of a scan the robot stood still through, the compensator's tilt
        calibrates the IMU's (see :mod:`services.nav.tilt`)."""
        t = self.ctx.clock.now_ns() / 1e9
        with self._lock:
            if m.state == ScannerState.SCANNING:
                if self._scan is None or self._scan[0] != m.scan_id:
                    self._scan = (m.scan_id, t)
                return
            if m.state != ScannerState.DONE or self._scan is None or self._scan[0] != m.scan_id:
                return
            _, since = self._scan
            self._scan = None
            if self._moving_until >= since:
                return  # moved during the scan: the reading is of another place
            # the compensator's axes are the scanner's, turned by its mount's yaw
            mount = rot_zyx(0.0, 0.0, self.mounts.scanner_yaw)
            roll, pitch = tilt_of(rot_zyx(m.roll, m.pitch, 0.0) @ mount.T)
            if self.tilt.compensator(t, roll, pitch):
                b = self.tilt.bias
                self.ctx.log.info(
                    "IMU tilt calibrated by the compensator at scan %d: bias roll %.3f, "
                    "pitch %.3f deg (%d scans)",
                    m.scan_id,
                    math.degrees(b[0]),
                    math.degrees(b[1]),
                    self.tilt.calibrations,
                )

    def _on_fix(self, m: NavSatFix) -> None:
        if m.fix_type.name not in self.cfg.fuse_fix_types:
            return
        x, y, z = self.frame.wgs84_to_field(m.latitude, m.longitude, m.altitude)
        cov3 = self.frame.enu_cov_to_field(m.position_covariance)
        mount = self.mounts.levers[m.antenna - 1]
        t = m.stamp_ns / 1e9
        now = self.ctx.clock.now_ns() / 1e9
        with self._lock:
            lx, ly, height = self.tilt.tilted(mount, now)
            lever = (lx, ly)
            xy = np.array([float(x), float(y)])
            if self.loc.update_antenna(t, xy, cov3[:2, :2], lever, name=str(m.antenna)):
                # only a fix the filter took counts: a refused one stamped far in
                # the future must not keep the robot "localized" for ever
                self._last_fix = max(self._last_fix, t)
            # without a tilt the antennas' heights above base_link are taken upright:
            # they sit symmetrically about it, so the errors cancel in the mean
            self.loc.update_height(t, float(z) - height, float(cov3[2, 2]))

    def _on_heading(self, m: GnssHeading) -> None:
        if m.valid:
            with self._lock:
                self.loc.update_heading(m.stamp_ns / 1e9, m.yaw, m.yaw_sd)

    def _on_scan(self, m: LaserScan) -> None:
        c = self.cfg
        with self._lock:
            x = self.loc.x
            f = self.follower
            leg = f.legs[f.leg] if f.active and f.legs else None
        pose = (float(x[0]), float(x[1]), float(x[2]))
        ranges = m.ranges.numpy()
        lidar, front = self.mounts.lidar, self.mounts.front
        box = (c.obstacle_distance_m, c.obstacle_half_width_m)
        if leg is not None:
            ends = (leg.x0, leg.y0, leg.x1, leg.y1)
            hits = hits_on_leg(
                ranges, m.angle_min, m.angle_increment, lidar, pose, ends, front, *box, self.crop
            )
            where = FIELD_FRAME
        else:
            hits = hits_ahead(ranges, m.angle_min, m.angle_increment, lidar, front, *box)
            where = BASE_FRAME
        said = self.obstacles.update(m.stamp_ns / 1e9, hits, where)
        if said and leg is not None:  # standing between routes, nothing waits on it
            at = f"; robot at ({pose[0]:.2f}, {pose[1]:.2f}, {math.degrees(pose[2]):.1f} deg)"
            held = self.obstacles.held
            (self.ctx.log.warning if held else self.ctx.log.info)("%s%s", said, at if held else "")

    def handle(self, cmd: NavCommand) -> NavReply:
        return self.routes.handle(cmd, self.ctx.clock.now_ns())

    def _on_alive(self, token: str, alive: bool) -> None:
        """A mission that dies stops the robot at once rather than at its lease's end
        (its token goes as its connection closes); the lease covers a hung or cut-off
        one. Routes sent by others (experiments, tests) are left to their leases."""
        a = parse_token(token)
        if a is None or a.service != "mission":
            return
        stopped = False
        with self._lock:
            if alive:
                self._missions.add(token)
            elif token in self._missions:
                self._missions.discard(token)
                if not self._missions and self.follower.active:
                    self.follower.abandon(f"{LEASE_ENDED}: the mission is gone ({a.machine})")
                    self.ctx.log.warning("mission gone: route %s stopped", self.follower.route_id)
                    stopped = True
        if stopped:  # now, not at the next tick: a tick is up to 5 cm at 1 m/s
            now = self.ctx.clock.now_ns()
            self.cmd_pub.put(Twist(stamp_ns=now, frame_id=BASE_FRAME, linear_x=0.0, angular_z=0.0))

    def _localized(self, t: float) -> bool:
        """Localized: the filter's uncertainty is within bounds *and* a fix was fused
        within ``max_fix_age_s``. Odometry alone carries the pose that long (the stated
        dead-reckoning allowance); without the age rule the filter's sigma grows past
        its bound only seconds into an RTK outage, metres later."""
        return self.loc.localized() and t - self._last_fix <= self.cfg.max_fix_age_s

    def run(self, stop: threading.Event) -> None:
        was_active = False
        for now in clk.ticks(self.ctx.clock, self.cfg.rate_hz, stop):
            t = now / 1e9
            with self._lock:
                self.loc.predict(t)
                x, cov = self.loc.x.copy(), self.loc.P[:3, :3].copy()
                localized = self._localized(t)
                tilt = self.tilt.tilt(t)
                sd, yaw_sd = pose_sds(cov)
                cmd = self.follower.step(
                    t, x[0], x[1], x[2], localized, self.obstacles.held, sd, yaw_sd
                )
                active = self.follower.active
                if cmd.v or cmd.w:
                    self._moving_until = t
                route_id, legs = self.follower.route_id, len(self.follower.legs)
                # sent under the lock: a route abandoned by another thread (the mission
                # gone) is never followed by this tick's older command
                if active or was_active:
                    self.cmd_pub.put(
                        Twist(stamp_ns=now, frame_id=BASE_FRAME, linear_x=cmd.v, angular_z=cmd.w)
                    )
            self.pose_pub.put(
                PoseEstimate(
                    stamp_ns=now,
                    frame_id=FIELD_FRAME,
                    x=x[0],
                    y=x[1],
                    yaw=x[2],
                    z=self.loc.z if math.isfinite(self.loc.var_z) else 0.0,
                    v=x[3],
                    w=x[4],
                    covariance=tuple(cov.ravel()),
                    localized=localized,
                    roll=tilt[0] if tilt else 0.0,
                    pitch=tilt[1] if tilt else 0.0,
                    tilted=tilt is not None,
                )
            )
            was_active = active
            if route_id:
                self.progress_pub.put(
                    NavProgress(
                        stamp_ns=now,
                        frame_id=FIELD_FRAME,
                        route_id=route_id,
                        state=cmd.state,
                        leg=cmd.leg,
                        legs=legs,
                        distance_to_go=cmd.distance_to_go,
                        cross_track=cmd.cross_track,
                        heading_error=cmd.heading_error,
                        detail=cmd.detail,
                    )
                )
            if cmd.event:
                level = "info" if cmd.state == NavState.ARRIVED else "warning"
                getattr(self.ctx.log, level)(
                    "route %s: %s%s", route_id, cmd.event, f": {cmd.detail}" if cmd.detail else ""
                )


def build(ctx: Context, cfg: NavConfig) -> NavService:
    return NavService(ctx, cfg)
