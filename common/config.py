"""Deploy manifests and service configs: TOML decoded into msgspec Structs.

A manifest (``deploy/<machine>.toml``) names the machine, its Zenoh endpoints, its
clock, and the services it runs with their config sections. Every config Struct
forbids unknown fields, so a typo is one clear error before anything starts::

    deploy/sim.toml: [services.gnss]: Object contains unknown field `buad`
"""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar

import msgspec
import zenoh

from common.messages.core import Namespace

C = TypeVar("C")


class ConfigError(ValueError):
    """A config or manifest is wrong; the message is one line naming file and key."""


class TlsConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """TLS for the links between machines (``tls/`` endpoints)."""

    root_ca: str
    """The certificate authority's certificate (PEM path) the peers' certificates are
    signed by."""
    certificate: str = ""
    """This machine's certificate (PEM path)."""
    private_key: str = ""
    """Its private key (PEM path)."""
    mutual: bool = False
    """Both sides present certificates signed by ``root_ca`` (mutual TLS; access control
    needs it)."""


Role = Literal["robot", "jetson", "basestation", "hub"]


class AccessConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Zenoh access control on this machine's router (made by :func:`common.acl.router_acl`;
    see docs/security.md). Needs mutual TLS: remote machines are known by their
    certificate's common name; any other link is denied everything."""

    remotes: dict[str, Role]
    """The certificate common name of each machine whose router links to this one ->
    its role: ``robot``, ``jetson``, ``basestation``, or ``hub`` for the router this one
    links to, which relays the others' traffic after checking it."""
    loopback: str = "lo"
    """The interface this machine's own processes reach the router on; they may do
    anything."""


class ZenohSettings(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """This machine's Zenoh: the services on this machine are peers that connect to the
    local router (and mesh among themselves on loopback). Multicast scouting is always
    off."""

    listen: list[str] = msgspec.field(default_factory=lambda: ["tcp/127.0.0.1:7447"])
    """Endpoints the router hosted by ``phenorover up`` listens on."""
    connect: list[str] = msgspec.field(default_factory=list)
    """Other machines' routers to link to."""
    local: list[str] = msgspec.field(default_factory=list)
    """Where this machine's services and CLI reach the router (empty: the plain
    ``listen`` endpoints, on loopback)."""
    tls: TlsConfig | None = None
    """TLS for the links between machines."""
    access: AccessConfig | None = None
    """Access control (none: no access control, as in the simulated deployment, loopback
    only)."""

    def local_endpoints(self) -> list[str]:
        """Where this machine's services and CLI reach its router: ``local``, else the
        plain ``listen`` endpoints on loopback (TLS is for the links between machines)."""
        plain = [e for e in self.listen if not e.startswith("tls/")]
        return self.local or [e.replace("0.0.0.0", "127.0.0.1") for e in plain]


class Manifest(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """One machine's deployment: its name, its Zenoh endpoints, its clock, the field,
    the robot, and the services it runs with their config sections."""

    machine: str
    """This machine's name: in liveliness tokens, ``phenorover status``, and the
    certificate common name the access control matches."""
    field: str = ""
    """The surveyed field: ``engr``, ``spl`` (the paper's fields, shipped) or a
    ``.toml``/``.geojson`` file. Its georeference defines the ``field`` frame for every
    service. No example is assumed: empty means none, and a manifest whose services need
    a field (sim, gnss, nav, reach-sim) is refused, so a robot never surveys an example
    field by accident."""
    robot: str = ""
    """The robot description (:mod:`common.robot`): a file, or the name of one shipped
    with phenorover (``husky``); empty is the shipped Husky A200,
    ``common/robots/husky.toml``."""
    namespace: Namespace = ""
    """The robot's, when several share a field (:mod:`common.keys`): its services' keys
    live under ``phenorover/<namespace>/`` (letters, digits, ``-``, ``_``; up to 32) and
    its services are named ``<namespace>.<service>`` where robots meet (docs/fleet.md);
    empty for a robot surveying alone."""
    clock: Literal["wall", "sim"] = "wall"
    """``wall``, or ``sim`` to follow the simulator's clock (a simulated world, which
    also places a field with no georeference at the default origin)."""
    lockstep: bool = False
    """With the sim clock: the world waits each step for the services that follow it
    (:mod:`common.lockstep`), so the same seed gives the same run at any speed and load
    (docs/simulation.md)."""
    lockstep_deadline_s: Annotated[float, msgspec.Meta(gt=0, le=600.0)] = 60.0
    """In lockstep, a service that has not acknowledged a step within this long (wall
    seconds) is hung: it is logged and stepped past."""
    zenoh: ZenohSettings = msgspec.field(default_factory=ZenohSettings)
    """This machine's router."""
    services: dict[str, dict[str, Any]] = msgspec.field(default_factory=dict)
    """One table per service this machine runs (``[services.<name>]``), decoded by the
    service's own config type."""
    run_dir: str = "runs"
    """Where missions write their folders (``<run_dir>/<mission>/``) and the simulator
    its snapshot."""
    hung_after_s: Annotated[float, msgspec.Meta(ge=3.0, le=600.0)] = 10.0
    """A service whose process lives but whose heartbeat (``health/<service>``, once a
    second) has been silent this long (wall seconds) is taken for hung: ``phenorover up``
    kills and restarts it, as one that died (docs/faults.md)."""


# Keys that left the service sections for the robot description (common/robot.py):
# (where in the section, as msgspec names it, key) -> where they are now. A manifest
# that still sets one is told so rather than only that the key is unknown.
MOVED_TO_ROBOT: dict[tuple[str, str], str] = {
    ("$", "antenna_levers"): "[[antennas]] x, y",
    ("$", "antenna_height_m"): "[[antennas]] z",
    ("$", "lidar_xy"): "[lidar]",
    ("$", "robot_front_m"): "[footprint] length",
    ("$", "max_speed"): "[limits] max_speed",
    ("$", "max_turn_rate"): "[limits] max_turn_rate",
    ("$", "placement"): "[scanner] and [[antennas]]",
    ("$.compass", "antenna1_xyz_m"): "[[antennas]]",
    ("$.compass", "antenna2_xyz_m"): "[[antennas]]",
    ("$.world", "scanner_mount"): "[scanner]",
    ("$.world.lidar", "mount_xyz"): "[lidar]",
    ("$.world.lidar", "mount_yaw_deg"): "[lidar] yaw_deg",
    ("$.world.robot", "length"): "[footprint]",
    ("$.world.robot", "width"): "[footprint]",
    ("$.world.robot", "track"): "track",
    ("$.world.robot", "wheelbase"): "wheelbase",
    ("$.world.robot", "max_v"): "[limits] max_speed",
    ("$.world.robot", "max_w"): "[limits] max_turn_rate",
    ("$.world.robot", "max_accel"): "[limits] max_accel",
    ("$.world.robot", "max_alpha"): "[limits] max_turn_accel",
}
_UNKNOWN = re.compile(r"Object contains unknown field `(\w+)`(?: - at `([^`]+)`)?")


def one_line(exc: Exception) -> str:
    """``exc``'s message on one line; for a key that moved to the robot description,
    where it went."""
    text = " ".join(str(exc).split())
    m = _UNKNOWN.fullmatch(text)
    moved = m and MOVED_TO_ROBOT.get((m.group(2) or "$", m.group(1)))
    if moved:
        text += (
            f": it moved to the robot description ({moved} in the file the manifest's "
            "`robot` names, common/robots/husky.toml by default)"
        )
    return text


def read_toml(path: Path) -> dict[str, Any]:
    try:
        with path.open("rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {one_line(exc)}") from None


def load_manifest(path: str | Path) -> Manifest:
    p = Path(path)
    try:
        return msgspec.convert(read_toml(p), type=Manifest)
    except msgspec.ValidationError as exc:
        raise ConfigError(f"{p}: {one_line(exc)}") from None


def decode_section(section: dict[str, Any], type_: type[C], where: str) -> C:
    """Validate a config section as ``type_``; ``where`` names it in errors."""
    try:
        return msgspec.convert(section, type=type_)
    except msgspec.ValidationError as exc:
        raise ConfigError(f"{where}: {one_line(exc)}") from None


def _parse_value(text: str) -> Any:
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text  # a bare word is a string: --set backend=sim


def apply_overrides(section: dict[str, Any], overrides: list[str]) -> dict[str, Any]:
    """Apply ``key.sub=value`` overrides (values in TOML syntax, bare words as strings)."""
    out = json.loads(json.dumps(section))  # deep copy of plain data
    for item in overrides:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ConfigError(f"--set {item!r}: expected key=value")
        node = out
        parts = key.split(".")
        for p in parts[:-1]:
            child = node.setdefault(p, {})
            if not isinstance(child, dict):
                raise ConfigError(f"--set {item!r}: {p} is not a table")
            node = child
        node[parts[-1]] = _parse_value(value)
    return out


def drop_none(x: Any) -> Any:
    """TOML has no null: an unset option is left out, as it would be written by hand."""
    if isinstance(x, dict):
        return {k: drop_none(v) for k, v in x.items() if v is not None}
    if isinstance(x, list):
        return [drop_none(v) for v in x]
    return x


def dump_toml(cfg: msgspec.Struct) -> str:
    """The config as TOML; optional keys left unset (None) are omitted, as TOML has no
    null and an absent key decodes back to None."""
    return msgspec.toml.encode(drop_none(msgspec.to_builtins(cfg))).decode()


def zenoh_config(
    mode: Literal["peer", "client", "router"],
    listen: list[str],
    connect: list[str],
    tls: TlsConfig | None = None,
    client_timeout_s: float = 10.0,
    access_control: dict[str, Any] | None = None,
) -> zenoh.Config:
    """An explicit Zenoh config: no multicast scouting, endpoints as given, and a fast
    reconnect (0.1-1 s) so a restarted peer is back within a second, not four.
    ``access_control`` is a Zenoh ACL section (:func:`common.acl.router_acl`); a client
    gives up opening after ``client_timeout_s`` with no router (``zenoh.ZError``)."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", json.dumps(listen))
    conf.insert_json5("connect/endpoints", json.dumps(connect))
    if mode == "client":
        # a CLI started right after `phenorover up` waits for the router to come up
        conf.insert_json5("connect/timeout_ms", str(int(client_timeout_s * 1000)))
    conf.insert_json5("connect/retry", json.dumps({"period_init_ms": 100, "period_max_ms": 1000}))
    # the advanced publisher's cache (history topics, common.keys.Topic) needs stamps
    conf.insert_json5("timestamping/enabled", "true")
    if tls is not None:
        t: dict[str, Any] = {"root_ca_certificate": tls.root_ca}
        if tls.certificate:
            t["listen_certificate"] = tls.certificate
            t["connect_certificate"] = tls.certificate
        if tls.private_key:
            t["listen_private_key"] = tls.private_key
            t["connect_private_key"] = tls.private_key
        if tls.mutual:
            t["enable_mtls"] = True
        conf.insert_json5("transport/link/tls", json.dumps(t))
    if access_control is not None:
        conf.insert_json5("access_control", json.dumps(access_control))
    return conf
