"""Turning a PlanRequest into a plan. Pure, and importable by worker processes."""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from pathlib import Path

import msgspec

from common.field import (
    Field,
    FieldError,
    FieldLayout,
    build_field,
    field_path,
    load_field,
)
from common.field_model import scanner_model
from common.messages.plan import PlanOptions, PlanRequest, PlanResult
from common.robot import Robot
from services.planner.budget import PlanBudget, check
from services.planner.core import plan
from services.planner.visibility import Chunks, Progress


def confine(name: str, allowed: Sequence[Path]) -> Path:
    """The field file ``name`` refers to, resolved (symlinks and ``..`` followed); raises
    FieldError unless it is one of ``allowed`` or lies under one of them."""
    path = field_path(name).resolve()
    roots = [a.resolve() for a in allowed]
    if any(path == r or path.is_relative_to(r) for r in roots):
        return path
    where = ", ".join(str(r) for r in roots) or "nowhere"
    raise FieldError(f"PlanRequest.name: {name!r} is outside the planner's field folders ({where})")


def resolve_field(
    req: PlanRequest, allowed: Sequence[Path] | None = None
) -> tuple[FieldLayout, Field]:
    """The request's field; raises FieldError naming the offending field. With
    ``allowed`` (the service), a ``name`` must be a file under one of those paths."""
    given = [
        n for n, v in (("layout", req.layout), ("geojson", req.geojson), ("name", req.name)) if v
    ]
    if len(given) != 1:
        raise FieldError(
            f"PlanRequest: give exactly one of layout, geojson, name (got {given or 'none'})"
        )
    if req.layout is not None:
        from common import fieldbook

        field = build_field(req.layout)
        # a layout sent whole must carry its book as records (no folder to read a CSV
        # from here), and they must match its plots
        fieldbook.check(req.layout, field, "PlanRequest.layout")
        return req.layout, field
    if req.geojson:
        from common.field_geojson import field_from_geojson

        return field_from_geojson(req.geojson.encode(), "PlanRequest.geojson")
    return load_field(req.name if allowed is None else confine(req.name, allowed))


def request_key(req: PlanRequest) -> str:
    """Identical requests (whatever their stamp) share a key."""
    body = msgspec.structs.replace(req, stamp_ns=0, frame_id="")
    return hashlib.sha256(msgspec.msgpack.encode(body)).hexdigest()


def compute(
    req: PlanRequest,
    progress: Progress | None = None,
    budget: PlanBudget | None = None,
    allowed: Sequence[Path] | None = None,
    chunks: Chunks | None = None,
) -> PlanResult:
    """Plan ``req``. Raises FieldError (OverBudget when the field is larger than
    ``budget``, default :class:`PlanBudget`) or ValueError, each one line.
    ``chunks``: where the visibility's chunks are cast (:mod:`.cluster`)."""
    layout, fld = resolve_field(req, allowed)
    check(fld, budget or PlanBudget(), req.scanner.max_range)
    return plan(
        layout,
        req.scanner,
        req.options,
        field=fld,
        progress=progress,
        chunks=chunks,
        battery=req.battery,
    )


def request_from_source(
    source: str, robot: Robot, options: PlanOptions, inline: bool
) -> PlanRequest:
    """A request for a field named on the command line, surveyed by ``robot``. With
    ``inline`` (a remote planner), a local file is sent as its content, so the planner
    need not have it."""
    path = Path(source)
    req = PlanRequest(
        name=source, scanner=scanner_model(robot), battery=robot.battery, options=options
    )
    if not inline or not path.exists():
        return req
    if path.suffix in (".geojson", ".json"):
        return msgspec.structs.replace(req, name="", geojson=path.read_text())
    layout, _ = load_field(path)
    return msgspec.structs.replace(req, name="", layout=layout)
