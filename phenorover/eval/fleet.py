"""Robots sharing a field in simulation, scored against the truth.

:func:`run` starts a simulated deployment of N robots on one machine as N + 1
machines would run it: the world (simulator and planner, a base station's) and each
robot (its devices, navigation and mission under its namespace), each with its own
Zenoh router, the robots' routers linked to the world's; with ``partition`` the link
of one robot passes a :class:`~phenorover.eval.relay.Relay` that is cut for a while
(the robot is then cut off from its peers and, in simulation, from the world that
feeds its devices: it stands until the link is back). It plans the field for N
robots, sends each robot the plan (each mission takes its share), can kill one
robot's mission supervisor mid-survey (the launcher starts it again; it resumes from
its log and its lane reservations from their file), and records every robot's true
pose. :func:`phenorover.eval.fleet_score.score` then says, from the truth and the
mission logs alone:

- the field time: from the first mission's start to the last one's end, sim time;
- lane-segment conflicts: instants at which two robots' bodies reach one segment of
  the lanes the survey drives (:mod:`common.lanes`, their true positions, each
  robot's footprint);
- every location scanned exactly once: the done steps of all the robots' logs
  against the plan's locations.
"""

from __future__ import annotations

import dataclasses
import os
import signal
import threading
import time
import tomllib
from pathlib import Path
from typing import Any

import msgspec

from common import keys
from common.client import open_client, wait_alive
from common.clock import NS
from common.config import load_manifest
from common.field import load_field
from common.files import write_atomic
from common.lanes import parked_pose
from common.messages.mission import MissionStart, MissionState
from common.messages.plan import PlanOptions, PlanResult
from common.messages.sim import TruthPose
from common.process import free_loopback_port
from common.transport import Bus
from phenorover.eval.relay import Relay
from phenorover.launcher import Launcher

DEPLOY = Path(__file__).resolve().parents[2] / "deploy" / "fleet"
ALIVE_S = 900.0  # how long a deployment may take to come up (the world's build)


@dataclasses.dataclass(frozen=True)
class Faults:
    """``kill``: (robot, sim s) its mission supervisor is killed at; ``partition``:
    (robot, sim s, wall s) its link is cut at, and for how long."""

    kill: tuple[str, float] | None = None
    partition: tuple[str, float, float] | None = None


@dataclasses.dataclass
class Outcome:
    """What a run left: each robot's run folder and mission, its true poses (sim ns,
    x, y) and the final states."""

    plan: PlanResult
    run_dirs: dict[str, Path]
    truth: dict[str, list[tuple[int, float, float]]]
    final: dict[str, MissionState | None]
    notes: list[str] = dataclasses.field(default_factory=list)


def names(robots: int) -> list[str]:
    return [f"rover{k}" for k in range(1, robots + 1)]


def write_deployment(
    out: Path,
    field: Path,
    robots: int,
    rtf: float,
    seed: int,
    partition: str | None,
    starts: list[tuple[float, float, float]] | None = None,
    scan_s: float | None = None,
) -> tuple[Path, dict[str, Path], Relay | None]:
    """The world's and each robot's manifests under ``out`` (from ``deploy/fleet``'s,
    on free loopback ports), and the relay of the partitioned robot's link; ``starts``:
    the robots' start poses (x, y, heading in degrees) instead of the world's homes;
    ``scan_s``: sim seconds a scan takes (None: the scanner profile's)."""
    world = tomllib.loads((DEPLOY / "world.toml").read_text())
    port = free_loopback_port()
    world |= {"field": str(field), "run_dir": str(out / "world")}
    world["zenoh"] = {"listen": [f"tcp/127.0.0.1:{port}"]}
    # the experiment measures the robots: no dashboard (its ports are a user's)
    world["services"].pop("viz", None)
    sim = world["services"]["sim"]
    sim |= {"real_time_factor": rtf, "seed": seed, "scan_dir": str(out)}
    sim["robots"] = [{"namespace": n} for n in names(robots)]
    for r, pose in zip(sim["robots"], starts or [], strict=False):
        r["start"] = list(pose)
    docs: dict[str, dict[str, Any]] = {"world": world}
    relay = None
    for k, name in enumerate(names(robots), start=1):
        rover = tomllib.loads((DEPLOY / "rover1.toml").read_text())
        target = port
        if name == partition:
            relay = Relay(port)
            target = relay.port
        rover |= {
            "machine": name,
            "namespace": name,
            "field": str(field),
            "run_dir": str(out / name),
            "zenoh": {
                "listen": [f"tcp/127.0.0.1:{free_loopback_port()}"],
                "connect": [f"tcp/127.0.0.1:{target}"],
            },
        }
        scanner = rover["services"]["scanner"]
        scanner["storage_dir"] = str(out / name / "scanner-card")
        if scan_s is not None:
            scanner["sim_scan_time_s"] = scan_s
        mission = rover["services"]["mission"]
        mission["share"] = k if robots > 1 else 0  # one robot takes a plan's one part
        mission["lanes"] = {"peers": [n for n in names(robots) if n != name]}
        docs[name] = rover
    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    for name, doc in docs.items():
        paths[name] = out / f"{name}.toml"
        write_atomic(paths[name], msgspec.toml.encode(doc))
    return paths.pop("world"), paths, relay


def starts(plan: PlanResult) -> list[tuple[float, float, float]]:
    """Where each robot of ``plan`` starts: at its home facing its way into the field,
    or alone without one at the Origin, as a one-robot plan's tour begins."""
    if plan.fleet is None:
        return [(plan.origin[0], plan.origin[1], 0.0)]
    out = []
    for part in plan.fleet.parts:  # the first leg: from home to its way in
        out.append(parked_pose(part.home, (part.legs[0].x1, part.legs[0].y1)))
    return out


def run(
    field: Path,
    out: Path,
    robots: int,
    options: PlanOptions,
    rtf: float = 4.0,
    seed: int = 1,
    faults: Faults = Faults(),
    timeout_s: float = 3600.0,
    say: Any = print,
    scan_s: float | None = None,
) -> Outcome:
    """One survey of ``field`` by ``robots`` robots (see the module docstring); the
    plan made with ``options`` for that many robots; ``scan_s``: sim seconds a scan
    takes (None: the scanner profile's). Raises RuntimeError, one line,
    when the deployment does not come up, a mission cannot start, or one has not ended
    within ``timeout_s``."""
    from services.planner.core import plan as make_plan

    layout, fld = load_field(field)
    plan = make_plan(layout, field=fld, options=msgspec.structs.replace(options, robots=robots))
    cut = faults.partition[0] if faults.partition else None
    world, rovers, relay = write_deployment(
        out, field, robots, rtf, seed, cut, starts(plan), scan_s
    )
    launchers = {"world": Launcher(world), **{n: Launcher(m) for n, m in rovers.items()}}
    outcome = Outcome(plan, {}, {n: [] for n in rovers}, {})
    try:
        for la in launchers.values():
            la.start()
        with open_client(world, []) as session:
            for la in launchers.values():  # a world of many plots takes minutes to grow
                machine = la.manifest.machine
                alive = wait_alive(session, set(la.children), ALIVE_S, machine=machine)
                if not alive:
                    raise RuntimeError(
                        f"{machine}: not alive after {ALIVE_S:g} s: {sorted(alive.missing)}"
                    )
            bus = Bus(session, "fleet-eval")
            try:
                _survey(bus, plan, rovers, launchers, relay, faults, timeout_s, outcome, say)
            finally:
                bus.close()
    finally:
        for la in launchers.values():
            la.stop()
        if relay is not None:
            relay.close()
    for name, m in rovers.items():
        state = outcome.final.get(name)
        if state is not None:
            outcome.run_dirs[name] = Path(load_manifest(m).run_dir) / state.mission
    return outcome


def _survey(
    bus: Bus,
    plan: PlanResult,
    rovers: dict[str, Path],
    launchers: dict[str, Launcher],
    relay: Relay | None,
    faults: Faults,
    timeout_s: float,
    outcome: Outcome,
    say: Any,
) -> None:
    lock = threading.Lock()

    def recorder(name: str) -> Any:
        def on(p: TruthPose) -> None:
            with lock:
                outcome.truth[name].append((p.stamp_ns, p.x, p.y))

        return on

    states = {}
    for name in rovers:
        bus.subscribe(keys.SIM_TRUTH.within(name), recorder(name))
        states[name] = bus.latest(keys.MISSION_STATE.within(name))
    clock = bus.latest(keys.SIM_CLOCK)
    for name in rovers:
        st = _start(bus, name, plan)
        say(f"{name}: mission {st.mission} started, {st.scans_total} locations")
    kill, part = faults.kill, faults.partition
    healed_at: float | None = None
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        time.sleep(0.5)
        c = clock.get()
        now = c.sim_ns / NS if c is not None else 0.0
        if kill is not None and now >= kill[1]:
            pid = launchers[kill[0]].pids()["mission"]
            os.kill(pid, signal.SIGKILL)
            outcome.notes.append(f"{kill[0]}'s mission supervisor killed at {now:.0f} s sim")
            say(outcome.notes[-1])
            kill = None
        if part is not None and relay is not None and now >= part[1]:
            relay.cut()
            healed_at = time.monotonic() + part[2]
            outcome.notes.append(f"{part[0]} cut off at {now:.0f} s sim for {part[2]:.0f} s wall")
            say(outcome.notes[-1])
            part = None
        if healed_at is not None and time.monotonic() >= healed_at and relay is not None:
            relay.restore()
            outcome.notes.append(f"{faults.partition[0]}'s link back at {now:.0f} s sim")  # type: ignore[index]
            say(outcome.notes[-1])
            healed_at = None
        finals = {n: s.get() for n, s in states.items()}
        if all(_ended(s) for s in finals.values()):
            break
    outcome.final = {n: s.get() for n, s in states.items()}
    late = {n: (s.phase.value if s else "no state") for n, s in outcome.final.items()}
    late = {n: phase for n, phase in late.items() if not _ended(outcome.final[n])}
    if late:  # an unfinished survey has no field time to score
        raise RuntimeError(f"not ended after {timeout_s:g} s of wall time: {late}")


def _ended(s: MissionState | None) -> bool:
    return s is not None and not s.in_progress and s.phase.value != "idle"


def _start(bus: Bus, name: str, plan: PlanResult) -> MissionState:
    """Start robot ``name``'s mission, asking again while its queryable is not yet
    reachable."""
    from common.rpc import RpcError, until_served

    cmd = MissionStart(mission=f"fleet-{name}", plan=plan)
    try:
        return until_served(lambda: bus.call(keys.MISSION_CMD.within(name), cmd, timeout=60), 60.0)
    except RpcError as exc:
        raise RuntimeError(f"{name}: mission did not start: {exc}") from None
