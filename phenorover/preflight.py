"""What is checked before a deployment starts.

:func:`preflight` is what the launcher runs before it opens the router or starts a
service: the manifest as written (:func:`validate`: every service section against its
config type, the Zenoh settings), the robot description (:func:`check_robot`), the
deployment's field (:func:`check_field`: it loads, and has a place on the globe where a
service needs its frame) and what each service would check only once started against
the field and the robot (:func:`service_problems`). A bad deployment is one error
line, never a service restarted in a loop. ``phenorover up --check`` runs the same
checks and says what each service would open (:mod:`phenorover.findings`).
"""

from __future__ import annotations

import dataclasses
import importlib
from pathlib import Path

import msgspec

from common.config import ConfigError, Manifest, ZenohSettings, decode_section, load_manifest
from common.field import Field, FieldError, FieldLayout, field_path, load_field
from common.field_geojson import default_origin_note, placed
from common.robot import Robot, load_robot
from services import JOBS, SERVICES
from services.nav.config import NavConfig, check_limits
from services.planner.budget import check as check_budget
from services.planner.config import PlannerConfig

# services that load the field frame at start: the field must have a place on the
# globe (:func:`common.field_geojson.placed`; viz and the planner do without one)
NEEDS_FRAME = ("gnss", "nav", "reach-sim")
# services that cannot start without the surveyed field
NEEDS_FIELD = ("sim", *NEEDS_FRAME)


def config_type(service: str, where: str) -> type[msgspec.Struct]:
    spec = SERVICES.get(service) or JOBS.get(service)
    if spec is None:
        known = ", ".join(sorted(SERVICES | JOBS))
        raise ConfigError(f"{where}: unknown service {service!r} (known: {known})")
    module, _, attr = spec.partition(":")
    t: type[msgspec.Struct] = getattr(importlib.import_module(module), attr)
    return t


def validate(path: Path) -> Manifest:
    """Load a manifest and check it as written, touching no other file: every service
    section against its config type, and the Zenoh settings (:func:`check_zenoh`).
    Raises ConfigError, one line naming the file and the key."""
    manifest = load_manifest(path)
    for name, section in manifest.services.items():
        where = f"{path}: [services.{name}]"
        decode_section(section, config_type(name, where), where)
    check_zenoh(manifest.zenoh, f"{path}: [zenoh]")
    return manifest


def loopback(endpoint: str) -> bool:
    host = endpoint.partition("/")[2].rpartition(":")[0].strip("[]")
    return host in ("localhost", "::1") or host.startswith("127.")


def check_zenoh(zs: ZenohSettings, where: str) -> None:
    """TLS endpoints need ``[zenoh.tls]``; access control needs mutual TLS (remote
    machines are known by their certificates) and no plain TCP off loopback."""
    for ep in [*zs.listen, *zs.connect]:
        if ep.startswith("tls/") and zs.tls is None:
            raise ConfigError(f"{where}: {ep} needs [zenoh.tls] (root_ca, certificate, ...)")
    if zs.access is None:
        return
    tls = zs.tls
    if tls is None or not (tls.mutual and tls.certificate and tls.private_key):
        raise ConfigError(
            f"{where}.access needs [zenoh.tls] with certificate, private_key and "
            "mutual = true: remote machines are known by their certificates"
        )
    for ep in zs.listen:
        if not ep.startswith("tls/") and not loopback(ep):
            raise ConfigError(
                f"{where}: listen {ep}: plain {ep.partition('/')[0]} off loopback would "
                "bypass TLS; use tls/ between machines"
            )


@dataclasses.dataclass(frozen=True)
class DeployedField:
    """The deployment's field as loaded; ``note``: the start-up line saying it was
    placed at the default origin (empty when it gives its own, or none is needed)."""

    layout: FieldLayout
    field: Field
    note: str = ""


def check_field(manifest: Manifest, path: Path) -> DeployedField | None:
    """The manifest's field loads, and where a service needs its frame it has a place
    on the globe by the one rule every service applies (:func:`placed`: its own
    origin, or in a simulated deployment the default one); a manifest whose services
    need a field names one. None: no field and none needed. Raises ConfigError."""
    needs = [s for s in NEEDS_FIELD if s in manifest.services]
    if not manifest.field:
        if needs:
            raise ConfigError(
                f"{path}: field: not set, and {', '.join(needs)} need the surveyed field "
                "(a .toml/.geojson field file, or an example name such as engr)"
            )
        return None
    try:
        layout, fld = load_field(manifest.field)
        note = ""
        if any(s in manifest.services for s in NEEDS_FRAME):
            where = placed(layout, field_path(manifest.field), manifest.clock)
            note = "" if where is layout else default_origin_note(layout)
    except FieldError as exc:
        raise ConfigError(f"{path}: field: {exc}") from None
    return DeployedField(layout, fld, note)


def check_robot(manifest: Manifest, path: Path) -> Robot:
    """The manifest's robot description. Raises ConfigError naming the file."""
    try:
        return load_robot(manifest.robot)
    except ConfigError as exc:
        raise ConfigError(f"{path}: robot: {exc}") from None


def service_problems(
    manifest: Manifest, robot: Robot | None, deployed: DeployedField | None
) -> list[tuple[str, str]]:
    """(service, problem) for what a service would refuse at start although its
    section decodes: settings checked against the robot (nav's follower limits) or the
    field (the planner's budget). ``robot``/``deployed`` None: not checked against."""
    out: list[tuple[str, str]] = []
    sections = manifest.services
    if "nav" in sections and robot is not None:
        nav = decode_section(sections["nav"], NavConfig, "[services.nav]")
        try:
            check_limits(nav, robot)
        except ConfigError as exc:
            out.append(("nav", str(exc)))
    if "planner" in sections and deployed is not None:
        planner = decode_section(sections["planner"], PlannerConfig, "[services.planner]")
        try:
            check_budget(deployed.field, planner.budget)
        except FieldError as exc:
            out.append(("planner", f"field {manifest.field}: {exc}"))
    return out


def preflight(path: Path, field: str | None = None) -> tuple[Manifest, list[str]]:
    """Everything checked before a deployment starts, as the launcher runs it; nothing
    is opened or started. ``field`` replaces the manifest's field for every service
    (``phenorover sim --field``). Returns the manifest as it will run and the notes for
    its start-up lines (a field placed at the default origin). Raises ConfigError, one
    line naming the file and the key."""
    manifest = validate(path)
    if field is not None:
        manifest = msgspec.structs.replace(manifest, field=field)
    robot = check_robot(manifest, path)
    deployed = check_field(manifest, path)
    if problems := service_problems(manifest, robot, deployed):
        raise ConfigError(f"{path}: {problems[0][1]}")
    return manifest, [deployed.note] if deployed is not None and deployed.note else []
