"""The simulated world's state on disk, so a restarted simulator continues it.

Every other service's sim clock ignores time that goes backwards (it only ever moves
forward), so a simulator that restarted at sim time 0 froze the whole deployment. The
simulator therefore saves, every ``snapshot_s`` of wall time and when it stops, what
is not rebuilt deterministically from the field and the config: the sim time, the
robot's true state and the noise generator's state. On start it continues from the
snapshot of the same world (same field, same world config) left by a simulator that
died (a crash, SIGKILL) under the same deployment, that is the same parent
process (the ``phenorover up`` launcher that restarts it, or a test). A simulator told
to stop (SIGTERM: the deployment is ending) marks its last snapshot closed, and a new
deployment, ``phenorover sim`` included, starts a new world at 0; so does one with
``resume = false``. A snapshot a little behind the deployment's clock is harmless: the
others' clocks stand still until the simulator catches up with them. Limitation: a
simulator SIGTERMed alone inside a running deployment starts afresh too, and the
others' clocks then wait for it as long as the world had run.

File: ``<run_dir>/sim/world.json``, written atomically and durably
(:func:`common.files.write_atomic`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import os
import time
from pathlib import Path

import msgspec
import numpy as np

from common.field import Field, FieldLayout
from common.files import write_atomic
from common.robot import Robot, default_robot
from services.sim.robot import RobotState
from services.sim.world_config import WorldConfig

log = logging.getLogger(__name__)
VERSION = 1


class Snapshot(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """``world``: fingerprint of the field and world config it belongs to;
    ``deployment``: :func:`deployment_id` of the simulator that wrote it; ``closed``:
    written by a simulator that was told to stop (nothing to continue); ``sim_ns``:
    sim time; ``wall_ns``: when it was written (Unix ns); ``robot``: the true
    :class:`RobotState` (field frame, m, rad, m/s, rad/s); ``rng``: the noise
    generator's state as JSON text (its integers exceed 64 bits)."""

    version: int = VERSION
    world: str
    deployment: str
    field: str
    sim_ns: int
    wall_ns: int
    robot: dict[str, float]
    rng: str
    closed: bool = False
    # the other robots of a shared world, in order after the first
    fleet: list[RobotSnapshot] = msgspec.field(default_factory=list)


class RobotSnapshot(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """One robot's part: its true state (with its battery's charge) and noise."""

    robot: dict[str, float]
    rng: str


# the battery's charge (Wh) among the robot's state
BATTERY_KEY = "battery_wh"


def snapshot_path(run_dir: Path) -> Path:
    return run_dir / "sim" / "world.json"


def deployment_id() -> str:
    """The parent process (pid and start time, so a reused pid differs): the same for
    a simulator and its restarts by one launcher, different for the next launcher.
    ``PHENOROVER_SIM_DEPLOYMENT`` names the deployment instead: a simulated power cut
    kills the launcher too, and the world (which has no power to lose) must go on."""
    named = os.environ.get("PHENOROVER_SIM_DEPLOYMENT")
    if named:
        return named
    ppid = os.getppid()
    try:
        with open(f"/proc/{ppid}/stat", "rb") as f:
            # field 22 is the start time; the name (field 2) may hold spaces, so split
            # after its closing parenthesis
            started = f.read().rsplit(b")", 1)[1].split()[19].decode()
    except (OSError, IndexError):
        started = "?"
    return f"{ppid}@{started}"


def fingerprint(
    layout: FieldLayout, field: Field, cfg: WorldConfig, robot: Robot | None = None
) -> str:
    """Identifies one world: the same field (layout and plot boxes), world config and
    robot description (default: the shipped one)."""
    h = hashlib.sha256(msgspec.json.encode(layout))
    h.update(np.ascontiguousarray(field.plot_boxes).tobytes())
    h.update(msgspec.json.encode(cfg))
    h.update(msgspec.json.encode(robot or default_robot()))
    return h.hexdigest()[:32]


def take(
    world: str,
    field: str,
    sim_ns: int,
    robots: list[tuple[RobotState, np.random.Generator, float | None]],
    closed: bool = False,
) -> Snapshot:
    """The snapshot of a world at one instant (the caller holds the world still):
    each robot's state, noise generator and battery charge (kept with its state)."""
    parts = [_part(*r) for r in robots]
    return Snapshot(
        closed=closed,
        world=world,
        deployment=deployment_id(),
        field=field,
        sim_ns=sim_ns,
        wall_ns=time.time_ns(),
        robot=parts[0].robot,
        rng=parts[0].rng,
        fleet=parts[1:],
    )


def _part(state: RobotState, rng: np.random.Generator, battery_wh: float | None) -> RobotSnapshot:
    robot = dataclasses.asdict(state)
    if battery_wh is not None:
        robot[BATTERY_KEY] = battery_wh
    return RobotSnapshot(robot=robot, rng=json.dumps(rng.bit_generator.state))


def robots(snap: Snapshot) -> list[RobotSnapshot]:
    """Every robot's part of ``snap``, the first first."""
    return [RobotSnapshot(robot=snap.robot, rng=snap.rng), *snap.fleet]


def save(path: Path, snap: Snapshot) -> None:
    """Write ``snap`` atomically (a crash mid-write keeps the previous one)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, msgspec.json.encode(snap), durable=True)


def load(path: Path, world: str, deployment: str | None = None) -> Snapshot | None:
    """The snapshot at ``path`` when it belongs to ``world`` and ``deployment`` (default:
    this process's); None (and a log line saying why) when there is none, it is
    unreadable, or it is another world's or an earlier deployment's."""
    try:
        snap = msgspec.json.decode(path.read_bytes(), type=Snapshot)
    except FileNotFoundError:
        return None
    except (OSError, msgspec.DecodeError) as exc:
        log.warning("%s: unreadable world snapshot, starting afresh: %s", path, exc)
        return None
    if snap.version != VERSION or snap.world != world:
        log.info("%s: snapshot of another world (field %s), starting afresh", path, snap.field)
        return None
    if snap.deployment != (deployment or deployment_id()):
        log.info("%s: snapshot of an earlier deployment, starting afresh", path)
        return None
    if snap.closed:
        log.info("%s: the last simulator was stopped, not lost: starting afresh", path)
        return None
    return snap


def restore(snap: Snapshot | RobotSnapshot, rng: np.random.Generator) -> RobotState:
    """The (first) robot's state of ``snap``; sets ``rng`` to its generator state."""
    known = {f.name for f in dataclasses.fields(RobotState)}
    state = RobotState(**{k: float(v) for k, v in snap.robot.items() if k in known})
    rng.bit_generator.state = json.loads(snap.rng)
    return state
