"""What a mission folder keeps beside its log, so that the survey can be redone or
re-registered later, anywhere, with what it ran with: the plan (``plan.json``), the
robot description (``robot.toml``) and the effective manifest (``manifest.toml``).
Each is written under a temporary name and renamed, so none is ever half written."""

from __future__ import annotations

from pathlib import Path

import msgspec
import tomli_w

from common.config import drop_none, load_manifest
from common.files import write_atomic
from common.messages.plan import PlanResult
from common.robot import RUN_COPY, Robot, dump_robot, robot_path

MANIFEST_COPY = "manifest.toml"


def effective_manifest(manifest: Path, field: str) -> bytes:
    """The deployment's manifest as this service loaded it, with the field as the
    deployment resolved it (a ``--field`` given to ``phenorover sim`` replaces the
    manifest's) and the robot description's file (its content is ``robot.toml``)."""
    m = msgspec.to_builtins(load_manifest(manifest))
    m["field"], m["robot"] = field, str(robot_path(m.get("robot", "")))
    head = f"# the manifest this mission ran with: {manifest}, field and robot resolved\n"
    return head.encode() + tomli_w.dumps(drop_none(m)).encode()


def write_run_files(
    folder: Path, plan: PlanResult, robot: Robot, manifest: Path | None, field: str
) -> None:
    write_atomic(folder / "plan.json", msgspec.json.encode(plan))
    write_atomic(folder / RUN_COPY, dump_robot(robot).encode())
    if manifest is not None:
        write_atomic(folder / MANIFEST_COPY, effective_manifest(manifest, field))
