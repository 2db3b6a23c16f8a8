"""Where a mission comes from: the plan a ``MissionStart`` asks for (a plan file in
the run folder, or the planner's), or a mission a stopped service left unfinished in
the run folder, and the folder and log of a new one. Every refusal is one line naming
what is wrong."""

from __future__ import annotations

import sqlite3
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import msgspec
import numpy as np

from common import keys
from common.battery import Pace
from common.field import FieldError, load_field
from common.field_model import scanner_model
from common.messages.mission import MissionStart
from common.messages.plan import PlanOptions, PlanRequest, PlanResult, read_plan
from common.service import Context
from common.transport import RequestError, RpcError
from services.mission.log import MissionLog
from services.mission.plan import Segment, segments
from services.mission.runfiles import write_run_files


def requested_plan(
    ctx: Context, cmd: MissionStart, timeout: float, pace: Pace, share: int = 0
) -> PlanResult:
    """The plan ``cmd`` asks for, at ``pace`` (its time and swaps), and of a plan split
    between robots this robot's ``share`` (:func:`own_share`); RequestError naming the
    field at fault."""
    plan = _plan(ctx, cmd, timeout, pace)
    if (cmd.plan is not None or cmd.plan_file) and not surveys_field(ctx.field, plan):
        what = "MissionStart.plan" if cmd.plan is not None else "MissionStart.plan_file"
        raise RequestError(f"{what}: a plan of field {plan.field}, not of this deployment's")
    return own_share(plan, share)


def own_share(plan: PlanResult, share: int) -> PlanResult:
    """What this robot surveys of ``plan``: the plan (the one part of a plan for one
    robot parked by its locations), or with ``share`` k its share of a plan split
    between robots (``phenorover plan --robots N``). RequestError when
    the two disagree: a split plan surveyed whole would scan every location twice."""
    if share == 0:
        if plan.fleet is not None and plan.share is None:
            n = len(plan.fleet.parts)
            if n == 1:  # one robot parked by its locations: the one share is all of it
                return plan.share_of(1)
            raise RequestError(
                f"the plan is split between {n} robots: set this robot's share "
                f"([services.mission] share, 1..{n})"
            )
        return plan
    if plan.share is not None:
        if plan.share != share:
            raise RequestError(f"the plan is robot {plan.share}'s share, this robot's is {share}")
        return plan
    try:
        return plan.share_of(share)
    except ValueError as exc:
        raise RequestError(f"[services.mission] share {share}: {exc}") from None


def _plan(ctx: Context, cmd: MissionStart, timeout: float, pace: Pace) -> PlanResult:
    if cmd.plan is not None:
        return cmd.plan
    field = ctx.field
    if cmd.field and cmd.field != field and Path(cmd.field).resolve() != Path(field).resolve():
        # one field for the whole deployment: the simulated world, the planner and
        # the mission must agree on what is being surveyed
        raise RequestError(
            f"MissionStart.field: {cmd.field!r} is not this deployment's field {field!r}"
        )
    if cmd.plan_file:
        path = Path(cmd.plan_file).resolve()
        if not path.is_relative_to(ctx.run_dir.resolve()):
            raise RequestError(
                f"MissionStart.plan_file: {cmd.plan_file} is outside the run folder {ctx.run_dir}"
            )
        try:
            return read_plan(path, f"MissionStart.plan_file: {cmd.plan_file}")
        except ValueError as exc:
            raise RequestError(str(exc)) from None
    try:
        return ctx.bus.call(
            keys.PLANNER_PLAN,
            PlanRequest(
                name=field,
                scanner=scanner_model(ctx.robot),
                battery=ctx.robot.battery,
                options=PlanOptions(pace=pace),
            ),
            timeout=timeout,
        )
    except RpcError as exc:
        raise RequestError(f"planner: {exc}") from None


def new_mission(
    ctx: Context, plan: PlanResult, name: str = ""
) -> tuple[str, MissionLog, list[Segment]]:
    """A new mission of ``plan`` (named ``name``, else after the field and the time):
    its log in ``<run_dir>/<name>/mission.db`` with a step per scan location in tour
    order, the run's files beside it, and the plan's segments. RequestError when the
    plan cannot be driven or the mission exists already."""
    try:
        segs = segments(plan)
    except ValueError as exc:
        raise RequestError(str(exc)) from None
    name = name or f"{plan.field}-{time.strftime('%Y%m%d-%H%M%S')}"
    path = ctx.run_dir / name / "mission.db"
    if path.exists():
        raise RequestError(f"MissionStart.mission: {name} exists already in {path.parent}")
    log = MissionLog(path)
    steps = []
    for k, s in enumerate(x for x in segs if x.cand_id is not None):
        x, y, yaw = s.end
        steps.append((k + 1, int(s.cand_id or 0), x, y, yaw))
    log.create(name, plan.field, ctx.clock.now_ns(), msgspec.json.encode(plan).decode(), steps)
    write_run_files(path.parent, plan, ctx.robot, ctx.manifest, ctx.field)
    return name, log, segs


@dataclass
class Unfinished:
    """A mission to resume: its log (open), its plan, whether its operator paused it."""

    mission: str
    log: MissionLog
    plan: PlanResult
    paused: bool


def unfinished(run_dir: Path, field: str, warn: Callable[[str], None]) -> Unfinished | None:
    """The newest mission in the run folder still running or paused, of this
    deployment's field. Another field's, or a log that cannot be read, is left as it
    is, each with one ``warn`` line saying why."""
    dbs = sorted(run_dir.glob("*/mission.db"), key=lambda p: p.stat().st_mtime)
    for path in reversed(dbs):
        log: MissionLog | None = None
        try:
            log = MissionLog(path)
            m = log.mission()
            if m is None or m["state"] not in ("running", "paused"):
                log.close()
                continue
            plan = msgspec.json.decode(m["plan_json"], type=PlanResult)
        except (sqlite3.Error, msgspec.DecodeError, TypeError) as exc:
            if log is not None:
                log.close()
            warn(f"{path}: not a readable mission log ({exc}): not resumed")
            continue
        if not surveys_field(field, plan):
            # another deployment's survey (another field): driving its route here
            # would be driving blind; it stays as it is for its own
            warn(
                f"mission {m['id']} surveys field {plan.field}, not this deployment's "
                f"({field}): not resumed"
            )
            log.close()
            continue
        return Unfinished(m["id"], log, plan, paused=m["state"] == "paused")
    return None


def surveys_field(field: str, plan: PlanResult) -> bool:
    """Whether ``plan`` is of ``field``: the same plots, wherever the field file lies
    and whatever it is called (a plan on the crop as measured keeps the field's
    plots as its footprints)."""
    try:
        _, fld = load_field(field)
    except FieldError:
        return False
    try:
        boxes = plan.plot_footprints()
    except ValueError:  # a plan whose boxes are not (P, 6) floats is of no field
        return False
    return boxes.shape == fld.plot_boxes.shape and bool(
        np.allclose(boxes, fld.plot_boxes, atol=1e-6)
    )
