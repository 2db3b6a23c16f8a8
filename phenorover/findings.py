"""``phenorover up --check``: what each service would open, and what is missing.

:func:`check` runs the checks the launcher runs before it starts anything
(:mod:`phenorover.preflight`) and says what each service would open (serial port, TCP
address, CAN channel, ROS 2 topics, folders, the field, TLS files), with one problem
line per device or file that is not there. Nothing is opened: devices and files are
only looked at (``/dev/ttyUSB0`` exists, ``/sys/class/net/can0`` exists, a folder is
writable), so it is safe beside a running deployment and on a machine with no hardware.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from common.config import ConfigError, Manifest, TlsConfig, ZenohSettings, decode_section
from common.robot import robot_path
from phenorover.certs import tls_problems
from phenorover.preflight import (
    DeployedField,
    check_field,
    check_robot,
    config_type,
    loopback,
    service_problems,
    validate,
)


@dataclasses.dataclass(frozen=True)
class Finding:
    """One thing a service would open, and why it cannot (``problem``), if it cannot."""

    what: str
    problem: str = ""


def _exists(path: str, kind: str) -> str:
    return "" if os.path.exists(path) else f"{path}: no such {kind}"


def _device(path: str) -> str:
    if not os.path.exists(path):
        return f"{path}: no such device"
    return "" if os.access(path, os.R_OK | os.W_OK) else f"{path}: not readable and writable"


def _folder(path: str) -> str:
    """A folder a service writes into: it exists and is writable, or can be made."""
    p = Path(path).absolute()
    while not p.exists():
        p = p.parent
    if not p.is_dir():
        return f"{path}: {p} is not a folder"
    return "" if os.access(p, os.W_OK | os.X_OK) else f"{path}: {p} is not writable"


def _gnss(cfg: Any) -> list[Finding]:
    if cfg.backend == "sim":
        return [Finding("simulated receivers (from the sim service)")]
    out = []
    for a in cfg.antennas:
        if cfg.backend == "nmea-serial":
            out.append(
                Finding(f"antenna {a.id}: serial {a.port} at {a.baud} baud", _device(a.port))
            )
        else:
            host = f"{a.host}:{a.tcp_port}"
            out.append(
                Finding(
                    f"antenna {a.id}: NMEA over TCP from {host}",
                    "" if a.host else f"antenna {a.id}: no host",
                )
            )
    return out


def _base(cfg: Any) -> list[Finding]:
    if cfg.backend == "sim":
        return [Finding("simulated base (from the sim service)")]
    via = (
        f"rmw_zenoh (domain {cfg.ros2_domain}, namespace {cfg.ros2_namespace})"
        if cfg.ros2_layout == "rmw_zenoh"
        else "zenoh-bridge-ros2dds"
    )
    return [
        Finding(
            f"ROS 2 topics through {via}: {cfg.ros2_cmd_vel} ({cfg.ros2_cmd_vel_type} out), "
            f"{cfg.ros2_odom} (Odometry in), {cfg.ros2_scan} (LaserScan in), "
            f"{cfg.ros2_imu} (Imu in)"
        )
    ]


def _scanner(cfg: Any) -> list[Finding]:
    if cfg.backend == "sim":
        return [
            Finding("simulated FARO on a virtual CAN bus in this process"),
            Finding(f"scan files in {cfg.storage_dir}", _folder(cfg.storage_dir)),
        ]
    bus = f"CAN {cfg.interface} {cfg.channel} at {cfg.bitrate} bit/s"
    problem = ""
    if cfg.interface == "socketcan":
        if not os.path.exists(f"/sys/class/net/{cfg.channel}"):
            problem = f"{cfg.channel}: no such CAN interface (see `ip link show`)"
    elif cfg.channel.startswith("/dev/"):  # slcan, serial: an adapter's tty
        problem = _device(cfg.channel.split("@")[0])
    # the scanner's card, mounted here: a scan is done only when its file is on it
    card = _exists(cfg.storage_dir, "folder (is the scanner's card mounted?)")
    return [Finding(bus, problem), Finding(f"scan files in {cfg.storage_dir}", card)]


def _viz(cfg: Any) -> list[Finding]:
    out = []
    if cfg.serve:
        out.append(
            Finding(
                f"rerun gRPC on {cfg.bind}:{cfg.grpc_port}, web viewer on {cfg.bind}:{cfg.web_port}"
            )
        )
    if cfg.save:
        out.append(Finding(f"recording to {cfg.save}"))
    return out or [Finding("no devices")]


def _reach_sim(cfg: Any) -> list[Finding]:
    out = []
    for o in cfg.outputs:
        if o.tcp_port is not None:
            port = o.tcp_port or "a free port"
            out.append(Finding(f"simulated Reach M2 {o.id}: NMEA TCP server on {cfg.host}:{port}"))
        if o.pty:
            out.append(Finding(f"simulated Reach M2 {o.id}: NMEA on a pseudo-terminal at {o.pty}"))
    return out or [Finding("no outputs")]


def _husky_sim(cfg: Any) -> list[Finding]:
    return [
        Finding(
            f"simulated Husky driver: ROS 2 node {cfg.node_name} over rmw_zenoh, domain "
            f"{cfg.domain_id}: {cfg.cmd_vel} in, {cfg.odom}, {cfg.scan} and {cfg.imu} out"
        )
    ]


def _faro_sim(cfg: Any) -> list[Finding]:
    return [
        Finding(f"simulated FARO: SLCAN on a pseudo-terminal at {cfg.link}"),
        Finding(f"scan files in {cfg.storage_dir}"),
    ]


DESCRIBE: dict[str, Callable[[Any], list[Finding]]] = {
    "gnss": _gnss,
    "base": _base,
    "scanner": _scanner,
    "viz": _viz,
    "reach-sim": _reach_sim,
    "husky-sim": _husky_sim,
    "faro-sim": _faro_sim,
}


def _tls(tls: TlsConfig, machine: str) -> list[Finding]:
    cert = Path(tls.certificate) if tls.certificate else None
    key = Path(tls.private_key) if tls.private_key else None
    problems = tls_problems(Path(tls.root_ca), cert, key, machine)
    files = [tls.root_ca, tls.certificate, tls.private_key]
    what = "mutual TLS with " if tls.mutual else "TLS with "
    first = problems[0] if problems else ""
    found = [Finding(what + ", ".join(f for f in files if f), first)]
    return found + [Finding("", p) for p in problems[1:]]


def _zenoh(zs: ZenohSettings) -> list[Finding]:
    out = [
        Finding(f"router listens on {', '.join(zs.listen)}"),
        Finding(f"router connects to {', '.join(zs.connect) or 'nobody'}"),
        Finding(f"services and the CLI reach it on {', '.join(zs.local_endpoints())}"),
    ]
    if zs.access is not None:
        remotes = ", ".join(f"{cn} as {role}" for cn, role in sorted(zs.access.remotes.items()))
        out.append(Finding(f"access control: default deny; remote machines: {remotes}"))
    elif all(loopback(e) for e in [*zs.listen, *zs.connect]):
        out.append(Finding("no access control: open to this machine only (loopback)"))
    else:
        out.append(Finding("no access control: anyone who reaches the router may do anything"))
    return out


def _robot_ok(manifest: Manifest) -> bool:
    try:
        robot_path(manifest.robot)
    except ConfigError:
        return False
    return True


def describe(manifest: Manifest, path: Path) -> list[tuple[str, Finding]]:
    """Every (section, finding) of a validated manifest, problems included: the
    launcher's checks (:mod:`phenorover.preflight`) as findings, not a first error."""
    found = [("zenoh", f) for f in _zenoh(manifest.zenoh)]
    if manifest.zenoh.tls is not None:
        found += [("tls", f) for f in _tls(manifest.zenoh.tls, manifest.machine)]
    field = Finding(manifest.field or "none")
    deployed: DeployedField | None = None
    try:
        deployed = check_field(manifest, path)
    except ConfigError as exc:
        field = Finding(field.what, str(exc).removeprefix(f"{path}: field: "))
    if deployed is not None and deployed.note:
        field = Finding(f"{field.what}: {deployed.note}")
    found.append(("field", field))
    robot_file = str(robot_path(manifest.robot)) if _robot_ok(manifest) else manifest.robot
    robot = None
    try:
        robot = check_robot(manifest, path)
        found.append(("robot", Finding(robot_file)))
    except ConfigError as exc:
        found.append(("robot", Finding(robot_file, str(exc).removeprefix(f"{path}: robot: "))))
    found.append(("run dir", Finding(manifest.run_dir, _folder(manifest.run_dir))))
    for name, section in manifest.services.items():
        where = f"[services.{name}]"
        cfg = decode_section(section, config_type(name, where), where)
        found += [(name, f) for f in DESCRIBE.get(name, lambda _: [Finding("no devices")])(cfg)]
    found += [(name, Finding("", p)) for name, p in service_problems(manifest, robot, deployed)]
    return found


def check(path: Path) -> tuple[list[str], list[str]]:
    """``phenorover up --check``: (report lines, problem lines). Raises ConfigError
    when the manifest itself is wrong."""
    manifest = validate(path)
    found = describe(manifest, path)
    width = max(len(s) for s, _ in found)
    report = [f"{path}: machine {manifest.machine}"]
    report += [
        f"  {s:<{width}}  {f.what}" + ("  [MISSING]" if f.problem else "")
        for s, f in found
        if f.what
    ]
    problems = [f"{path}: {s}: {f.problem}" for s, f in found if f.problem]
    return report, problems
