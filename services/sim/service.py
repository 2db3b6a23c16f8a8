"""The simulator's Zenoh shell: steps the world in sim time, publishes the clock,
ground truth (for evaluation only) and what the simulated devices sense, and renders
scans on request. Time stands still while a scan is rendered: in the world a scan
is measured, not computed.

The world is the deployment's field (``--field`` or the manifest's ``field``), the
same one every other service plans and navigates in. Its state is saved every
``snapshot_s`` (see :mod:`services.sim.snapshot`), and a restarted simulator carries
on from it. Rendered scans go only under the scan folder (see
:mod:`services.sim.storage`). The true plants are written once at start, for the
evaluation only (``<run_dir>/sim/plants.truth.json``, :mod:`services.sim.truth_file`)."""

from __future__ import annotations

import math
import os
import threading
import time
from functools import partial
from pathlib import Path

import msgspec
import numpy as np

from common import keys
from common.clock import NS
from common.config import ConfigError, load_manifest
from common.field import load_field
from common.messages.sim import RenderReply, RenderRequest, SimClock, SimRun
from common.pointcloud import PosedScan, write_e57
from common.service import Context
from common.transport import RequestError
from services.sim import snapshot
from services.sim.barrier import Barrier
from services.sim.battery import SimBattery
from services.sim.config import SimConfig
from services.sim.faults import FaultSchedule
from services.sim.plant_truth import write_plant_truth
from services.sim.robot import RobotState
from services.sim.robots import SEED_STRIDE, SimRobot, starts
from services.sim.storage import PathRefused, confine
from services.sim.truth_file import scan_truth, write_truth
from services.sim.world import World


class SimService:
    def __init__(self, ctx: Context, cfg: SimConfig) -> None:
        self.ctx, self.cfg = ctx, cfg
        layout, fld = load_field(ctx.field)
        ctx.log.info("world: field %s (%s), %d plots", fld.name, ctx.field, fld.n_plots)
        self.world = World(layout, fld, cfg.world, ctx.robot)
        ctx.log.info(
            "world: %d sphere targets, %s", len(self.world.sphere_centres), self.world.placement
        )
        self.scan_root = Path(cfg.scan_dir or ctx.run_dir)
        self.sim_ns = 0
        self.faults = FaultSchedule(cfg.faults)
        self.snap_path = snapshot.snapshot_path(ctx.run_dir)
        try:  # evaluation only: the true plants, beside the world snapshot
            ctx.log.info("plants' truth: %s", write_plant_truth(self.snap_path.parent, self.world))
        except OSError as exc:  # a run folder we cannot write must not stop the world
            ctx.log.warning("cannot write the plants' truth: %s", exc)
        self.world_id = snapshot.fingerprint(layout, fld, cfg.world, ctx.robot)
        self._lock = threading.Lock()  # held while stepping or rendering
        try:
            placed = starts(cfg, fld)
        except ValueError as exc:
            raise ConfigError(f"[services.sim] {exc}") from None
        self.robots = [
            SimRobot(ctx, cfg, self.world, self.faults, k, ns, start, self._lock)
            for k, (ns, start) in enumerate(placed)
        ]
        for r in self.robots:
            r.others = [o for o in self.robots if o is not r]
            if r.namespace:
                ctx.log.info("robot %s at (%.2f, %.2f)", r.namespace, r.state.x, r.state.y)
        if cfg.resume:
            self._resume()
        bus = ctx.bus
        self.clock_pub = bus.publisher(keys.SIM_CLOCK)
        for r in self.robots:
            bus.serve(keys.SIM_RENDER.within(r.namespace), partial(self.render, r))
        self.barrier: Barrier | None = None
        self._held = threading.Event()
        self.real_time_factor = cfg.real_time_factor  # paced at; SIM_RUN may change it
        bus.serve(keys.SIM_RUN, self._run)
        if ctx.inbox is not None and ctx.manifest is not None:
            self.barrier = Barrier(bus, load_manifest(ctx.manifest).lockstep_deadline_s)
            if cfg.start_held:
                self._held.set()
            bus.report("lockstep_late", lambda: self.barrier.late if self.barrier else 0)
        self._tick = SimClock(sim_ns=0)

    @property
    def state(self) -> RobotState:
        """The first robot's true state (the only one's, without ``robots``)."""
        return self.robots[0].state

    def _resume(self) -> None:
        snap = snapshot.load(self.snap_path, self.world_id)
        if snap is None:
            return
        saved = snapshot.robots(snap)
        if len(saved) != len(self.robots):
            self.ctx.log.warning("%s: another number of robots, starting afresh", self.snap_path)
            return
        try:
            restored = [
                snapshot.restore(r, robot.rng) for r, robot in zip(saved, self.robots, strict=True)
            ]
        except (ValueError, TypeError, KeyError) as exc:
            self.ctx.log.warning("%s: cannot restore (%s), starting afresh", self.snap_path, exc)
            for k, robot in enumerate(self.robots):
                robot.rng = np.random.default_rng(self.cfg.seed + SEED_STRIDE * k)
            return
        self.sim_ns = snap.sim_ns
        for robot, state, r in zip(self.robots, restored, saved, strict=True):
            robot.state, robot.sim_ns = state, snap.sim_ns
            charge = r.robot.get(snapshot.BATTERY_KEY)
            robot.battery = SimBattery(self.ctx.robot.battery, self.ctx.log, charge)
            robot.devices.battery = robot.battery
        self.ctx.log.info(
            "continuing the world of %s from sim time %.1f s (saved %.1f s ago), robot at "
            "(%.2f, %.2f)",
            self.snap_path,
            snap.sim_ns / NS,
            (time.time_ns() - snap.wall_ns) / NS,
            self.state.x,
            self.state.y,
        )

    def save_snapshot(self, closed: bool = False) -> None:
        """Save the world's state (atomically; the world holds still while it is read);
        ``closed``: the simulator was told to stop, so there is nothing to continue."""
        with self._lock:
            snap = snapshot.take(
                self.world_id,
                self.world.field.name,
                self.sim_ns,
                [(r.state, r.rng, r.battery.charge_wh) for r in self.robots],
                closed,
            )
        snapshot.save(self.snap_path, snap)

    def _snapshots(self, stop: threading.Event) -> None:
        while not stop.wait(self.cfg.snapshot_s):
            try:
                self.save_snapshot()
            except OSError as exc:  # a full disk must not stop the world
                self.ctx.log.warning("cannot save the world snapshot: %s", exc)

    def render(self, robot: SimRobot, req: RenderRequest) -> RenderReply:
        try:
            path = confine(req.path, self.scan_root, ".e57", "RenderRequest.path")
        except PathRefused as exc:
            raise RequestError(str(exc)) from None
        t0 = time.monotonic()
        with self._lock:  # the world (and its clock) stands still during the scan
            st, rng = robot.state, robot.rng
            pose = self.world.scanner_pose(st)
            settings = msgspec.structs.replace(self.cfg.scan, step_deg=req.step_deg)
            scan = self.world.render_scan(pose, settings, rng)
            sd = math.radians(self.cfg.inclinometer_sd_deg)
            # the compensator measures the scanner's tilt: the base's, turned by the
            # mount's yaw (ZYX: pitch from r20, roll from r21 and r22)
            true_pitch = -math.asin(min(1.0, max(-1.0, float(pose[2, 0]))))
            true_roll = math.atan2(float(pose[2, 1]), float(pose[2, 2]))
            pitch = true_pitch + float(rng.normal(0.0, sd))
            roll = true_roll + float(rng.normal(0.0, sd))
            path.parent.mkdir(parents=True, exist_ok=True)
            card = PosedScan.as_scanned(scan.points, scan.intensity, path.stem)
            write_e57(path, [card], durable=True)
            # evaluation only: lets `phenorover register` score against the truth
            write_truth(path, scan_truth(self.sim_ns, pose, st))
        return RenderReply(
            stamp_ns=self.sim_ns,
            path=str(path),
            points=len(scan.points),
            pitch=pitch,
            roll=roll,
            render_s=time.monotonic() - t0,
        )

    def _run(self, req: SimRun) -> SimClock:
        """Let a world started held step, at the real-time factor asked for if any."""
        if req.real_time_factor is not None and req.real_time_factor != self.real_time_factor:
            self.ctx.log.info("real-time factor %g from now on", req.real_time_factor)
            self.real_time_factor = req.real_time_factor
        self._held.clear()
        return self._tick

    def _hold(self, stop: threading.Event) -> None:
        """Publish nothing until asked to run, then call the roll (:mod:`common.lockstep`):
        the first step then expects all that was published while held."""
        assert self.barrier is not None
        self.ctx.log.info("held at sim time %.2f s until asked to run", self.sim_ns / NS)
        while self._held.is_set():
            if stop.wait(0.05):
                return
        self._tick = SimClock(stamp_ns=self.sim_ns, sim_ns=self.sim_ns, step=0, roll_call=True)
        self.clock_pub.put(self._tick)
        # every service up answers it, however slowly a loaded machine brought it up
        self.barrier.wait(self.sim_ns - 1, lambda: self.clock_pub.put(self._tick), stop, True)

    def _await_step(self, stop: threading.Event) -> None:
        """Lockstep: wait for every participant's acknowledgement of this step, then
        take in the wheel commands they counted in it."""
        assert self.barrier is not None and self.ctx.inbox is not None
        self.barrier.wait(self.sim_ns, lambda: self.clock_pub.put(self._tick), stop)
        thunks, _ = self.ctx.inbox.take(self._expect(self.barrier), self.barrier.deadline_s)
        for thunk in thunks:  # each takes the world's lock itself
            thunk()

    def _expect(self, b: Barrier) -> dict[str, int]:
        """What a step expects delivered: the participants' and the world's own."""
        return b.expect(self.ctx.bus.sender, self.ctx.bus.counts())

    def _step(self, dt: float) -> None:
        self.sim_ns += int(dt * NS)
        for r in self.robots:
            r.step(dt, self.sim_ns)

    def run(self, stop: threading.Event) -> None:
        saver = None
        if self.cfg.snapshot_s > 0:
            saver = threading.Thread(target=self._snapshots, args=(stop,), daemon=True)
            saver.start()
        told = False
        try:
            self._loop(stop)
            told = True  # the loop ends only when stop is set: SIGTERM, not a crash
        finally:
            stop.set()
            for r in self.robots:
                self.ctx.log.info(
                    "%s%s", f"{r.namespace}: " if r.namespace else "", r.battery.summary()
                )
            if saver is not None:
                saver.join(timeout=2.0)
                try:
                    self.save_snapshot(closed=told)
                except OSError as exc:
                    self.ctx.log.warning("cannot save the world snapshot: %s", exc)

    def _loop(self, stop: threading.Event) -> None:
        dt = 1.0 / self.cfg.clock_hz
        t_next = time.monotonic()
        k = 0
        if self.sim_ns > 0:  # a world carried on from its snapshot is not held again
            self._held.clear()
        if self._held.is_set():
            self._hold(stop)
            t_next = time.monotonic()
        while not stop.is_set():
            with self._lock:
                # what the devices sense, then the tick expecting it
                for r in self.robots:
                    r.publish(k, self.sim_ns)
                b = self.barrier
                self._tick = SimClock(
                    stamp_ns=self.sim_ns,
                    sim_ns=self.sim_ns,
                    real_time_factor=self.real_time_factor,
                    step=-1 if b is None else k,
                    expect={} if b is None else self._expect(b),
                )
                self.clock_pub.put(self._tick)
            if self.barrier is not None:
                self._await_step(stop)
            with self._lock:
                self._step(dt)
            k += 1
            t_next += dt / self.real_time_factor
            delay = t_next - time.monotonic()
            if delay > 0:
                if stop.wait(delay):
                    break
            elif delay < -1.0:  # fell behind (a render, a slow machine): do not race to catch up
                t_next = time.monotonic()


def build(ctx: Context, cfg: SimConfig) -> SimService:
    # in lockstep (an inbox) every step waits for the world and the world for every
    # step: a lowered simulator would only hold each step up, never yield to anyone
    if cfg.nice and ctx.inbox is None:
        try:
            os.nice(cfg.nice)
        except OSError as exc:  # not allowed here: the world keeps the services' pace
            ctx.log.warning("cannot lower the simulator's priority (nice %d): %s", cfg.nice, exc)
    return SimService(ctx, cfg)
