"""``phenorover mission start|pause|resume|abort|status`` (typed queries to the mission
service, from any machine) and ``phenorover sim``: a whole survey in simulation."""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

from common import keys
from common.client import add_connection_arguments
from common.config import ConfigError, load_manifest
from common.keys import NAMESPACE_RE
from common.messages.mission import (
    FINAL_PHASES,
    MissionAbort,
    MissionCommand,
    MissionEvent,
    MissionPause,
    MissionPhase,
    MissionResume,
    MissionStart,
    MissionState,
    MissionStatusQuery,
)
from common.messages.plan import read_plan
from common.rpc import until_served
from common.transport import Bus, RpcError


def add_mission_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("action", choices=["start", "pause", "resume", "abort", "status"])
    p.add_argument("--field", default="", help="the deployment's field (default: its own)")
    p.add_argument("--plan-file", default="", help="a plan.json on the mission's host")
    p.add_argument(
        "--plan", type=Path, default=None, help="a plan.json here, sent with the command"
    )
    p.add_argument(
        "--robot",
        default=None,
        metavar="NAMESPACE",
        help="the robot to command, by its namespace (default: the manifest's)",
    )
    p.add_argument("--name", default="", help="mission name (default: field and time)")
    add_connection_arguments(p)


def describe(s: MissionState) -> str:
    """One line: phase, scans, distance (driven, measured; the plan's length beside it,
    labelled planned); a finished survey that left locations unscanned says how many."""
    missed = s.scans_total - s.scans_done
    return (
        f"{s.mission or '-'}: {s.phase.value}, {s.scans_done}/{s.scans_total} scans done, "
        f"{s.scans_failed} failed, {s.distance_m:.1f} m driven (measured"
        + (f"; {s.planned_m:.1f} m planned)" if s.planned_m > 0 else ")")
        + (f" ({s.detail})" if s.detail else "")
        + (
            f"; {missed} of {s.scans_total} locations NOT scanned"
            if s.phase == MissionPhase.DONE and missed > 0
            else ""
        )
    )


def cmd_mission(args: argparse.Namespace) -> int:
    from common.client import connect_or_explain

    prog = f"phenorover mission {args.action}"
    try:
        plan = None if args.plan is None else read_plan(args.plan, f"--plan {args.plan}")
        namespace = robot_namespace(args.robot, args.manifest)
    except (ValueError, ConfigError) as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
    start = MissionStart(mission=args.name, field=args.field, plan_file=args.plan_file, plan=plan)
    commands: dict[str, MissionCommand] = {
        "start": start,
        "pause": MissionPause(),
        "resume": MissionResume(),
        "abort": MissionAbort(),
        "status": MissionStatusQuery(),
    }
    cmd = commands[args.action]
    session = connect_or_explain(prog, args.manifest, args.connect, service="mission")
    if session is None:
        return 2  # the line saying which endpoint could not be reached is printed
    with session:
        bus = Bus(session, "cli", namespace=namespace)
        try:
            print(describe(bus.call(keys.MISSION_CMD, cmd, timeout=330)))
        except RpcError as exc:
            print(f"phenorover mission {args.action}: {exc}", file=sys.stderr)
            return 1
        finally:
            bus.close()
    return 0


def robot_namespace(robot: str | None, manifest: Path | None) -> str:
    """The namespace of the robot a command is for: ``--robot``, else the manifest's
    (:mod:`common.keys`). ValueError for one that cannot be a key's chunk."""
    if robot is None:
        from common.client import DEFAULT_MANIFEST

        return load_manifest(manifest or DEFAULT_MANIFEST).namespace
    if not NAMESPACE_RE.fullmatch(robot):
        raise ValueError(f"--robot {robot!r}: a namespace is up to 32 letters, digits, - or _")
    return robot


def add_command(p: argparse.ArgumentParser) -> None:
    """``phenorover mission``."""
    add_mission_arguments(p)
    p.set_defaults(func=cmd_mission)


def _call(bus: Bus, cmd: MissionCommand) -> MissionState:
    """One mission command; a service that is alive but not serving yet (no reply)
    is asked again for up to 30 s."""
    return until_served(lambda: bus.call(keys.MISSION_CMD, cmd, timeout=330), 30.0)


def run_survey(
    bus: Bus,
    field: str,
    timeout: float,
    problems: list[str] | None = None,
    new: bool = False,
    started: Callable[[], object] | None = None,
) -> MissionState | None:
    """Start a survey and print a line per step until it ends; the final state (None
    when it could not start). A mission the service resumed (the deployment was stopped
    mid-survey) is followed to its end instead, or with ``new`` aborted first (its log
    and scans stay). ``problems`` gets the text of every error event of the mission (a
    location skipped or failed, and why). ``started`` is called once the mission is
    (a world held until then is let run by it)."""
    seen: list[MissionEvent] = []
    heard = threading.Condition()

    def on_event(e: MissionEvent) -> None:
        print(f"  [{e.stamp_ns / 1e9:8.1f} s sim] {e.level}: {e.text}", flush=True)
        with heard:
            seen.append(e)
            heard.notify_all()

    bus.subscribe(keys.MISSION_EVENT, on_event)
    state = bus.latest(keys.MISSION_STATE)
    try:
        s = _call(bus, MissionStatusQuery())
        if s.in_progress and new:
            print(f"aborting mission {s.mission}, left unfinished (its log and scans stay)")
            _call(bus, MissionAbort())
            gone = state.wait_for(lambda x: x.mission == s.mission and x.phase in FINAL_PHASES, 60)
            if gone is None:
                print(f"phenorover sim: mission {s.mission} did not abort in 60 s", file=sys.stderr)
                return None
        if s.in_progress and not new:
            print(
                f"mission {s.mission} was interrupted and is resumed ({s.scans_done}/"
                f"{s.scans_total} scans done before); following it to its end "
                "(--new aborts it and starts a new survey)",
                flush=True,
            )
        else:
            s = _call(bus, MissionStart(field=field))
            print(f"mission {s.mission} started", flush=True)
        if started is not None:
            started()
    except RpcError as exc:
        print(f"phenorover sim: {exc}", file=sys.stderr)
        return None
    last = ""
    end = time.monotonic() + timeout
    final: MissionState | None = None
    while time.monotonic() < end:
        st = state.wait_for(lambda x: x.mission == s.mission, timeout=2.0)
        if st is None:
            continue
        line = describe(st)
        if line != last:
            print(line, flush=True)
            last = line
        if st.phase in FINAL_PHASES:
            final = st
            break
        time.sleep(0.5)
    else:
        print(f"phenorover sim: mission not finished after {timeout:.0f} s", file=sys.stderr)
        final = state.get()
    if problems is not None:
        # events come on their own subscriber, unordered with the state: the mission's
        # own last word ("mission NAME done", "... aborted") says every event before it
        # is in
        word = f"mission {s.mission} "
        with heard:
            heard.wait_for(
                lambda: any(e.mission == s.mission and e.text.startswith(word) for e in seen),
                timeout=5.0,
            )
        problems.extend(e.text for e in list(seen) if e.mission == s.mission and e.level == "error")
    return final
