"""The simulated deployments open no socket beyond loopback.

For each of ``deploy/sim.toml`` and ``deploy/hil.toml``, the whole deployment runs under
``phenorover up``; once every service is alive and every listener its manifest
configures is up, every TCP and UDP socket of the launcher's process tree (services,
their workers and helpers, the Zenoh router in the launcher itself) must have a local
address in 127.0.0.0/8 (or ::1): listening, bound or connected.

The manifest run is the shipped one with only its port numbers (each replaced by a free
port, the same everywhere it appears, defaults included), its run folder (a temporary
one) and its field (the tiny test field) changed: the addresses are the shipped ones,
and the test can run beside a deployment already using the shipped ports.
"""

from __future__ import annotations

import dataclasses
import ipaddress
import os
import re
import select
import signal
import struct
import time
import tomllib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import tomli_w
import zenoh

from common.client import wait_alive
from common.config import load_manifest, zenoh_config
from services import SERVICES
from services.viz.config import VizConfig
from tests.conftest import REPO, Procs, free_port

TINY = REPO / "tests" / "data" / "tiny.toml"
ENDPOINT = re.compile(r"((?:tcp|udp|tls|quic)/.+):(\d+)")
TCP_STATES = {"01": "ESTABLISHED", "02": "SYN_SENT", "0A": "LISTEN"}


@dataclasses.dataclass(frozen=True)
class Sock:
    """One socket of a process: ``kind`` is tcp, tcp6, udp or udp6; ``state`` the TCP
    state (LISTEN, ESTABLISHED, ...; "" for UDP)."""

    kind: str
    ip: ipaddress.IPv4Address | ipaddress.IPv6Address
    port: int
    state: str
    pid: int
    who: str

    @property
    def loopback(self) -> bool:
        ip = self.ip
        if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
            ip = ip.ipv4_mapped
        return ip.is_loopback

    def __str__(self) -> str:
        host = f"[{self.ip}]" if self.ip.version == 6 else str(self.ip)
        return f"{self.who} (pid {self.pid}): {self.kind} {host}:{self.port} {self.state}".strip()


def _address(text: str) -> tuple[ipaddress.IPv4Address | ipaddress.IPv6Address, int]:
    """A /proc/net address ``HEX:PORT``: the address is 32-bit words in host order."""
    hexaddr, hexport = text.split(":")
    words = [int(hexaddr[i : i + 8], 16) for i in range(0, len(hexaddr), 8)]
    raw = b"".join(struct.pack("=I", w) for w in words)
    return ipaddress.ip_address(raw), int(hexport, 16)


def _table(pid: int, kind: str) -> Iterator[tuple[str, str, str]]:
    """(local address, TCP state, inode) of every socket in ``pid``'s network namespace."""
    try:
        lines = Path(f"/proc/{pid}/net/{kind}").read_text().splitlines()[1:]
    except OSError:
        return
    for line in lines:
        f = line.split()
        yield f[1], f[3], f[9]


def _parents() -> dict[int, int]:
    out = {}
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                stat = Path(f"/proc/{d}/stat").read_text()
            except OSError:
                continue  # gone meanwhile
            out[int(d)] = int(stat.rsplit(")", 1)[1].split()[1])
    return out


def _name(pid: int) -> str:
    """``services.viz`` for ``python -m services.viz ...``, else the program's name."""
    try:
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace").split("\0")
    except OSError:
        return "?"
    if "-m" in argv[:-1]:
        rest = argv[argv.index("-m") + 1 :]
        return " ".join(rest[:2]) if rest[0] == "phenorover" else rest[0]
    return Path(argv[0]).name


def process_tree(root: int) -> dict[int, str]:
    """``root`` and its descendants, each named by its ancestry (``up > services.viz >
    rerun``)."""
    parents = _parents()
    names = {root: _name(root)}
    grew = True
    while grew:
        grew = False
        for pid, ppid in parents.items():
            if ppid in names and pid not in names:
                names[pid] = f"{names[ppid]} > {_name(pid)}"
                grew = True
    return names


def sockets(root: int) -> list[Sock]:
    """Every TCP and UDP socket held by ``root``'s process tree."""
    out = []
    for pid, who in process_tree(root).items():
        inodes = set()
        try:
            fds = os.listdir(f"/proc/{pid}/fd")
        except OSError:
            continue
        for fd in fds:
            try:
                target = os.readlink(f"/proc/{pid}/fd/{fd}")
            except OSError:
                continue
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
        for kind in ("tcp", "tcp6", "udp", "udp6"):
            for local, state, inode in _table(pid, kind):
                if inode in inodes:
                    ip, port = _address(local)
                    tcp = TCP_STATES.get(state, state) if kind.startswith("tcp") else ""
                    out.append(Sock(kind, ip, port, tcp, pid, who))
    return out


def private_copy(shipped: Path, tmp: Path) -> tuple[Path, set[int]]:
    """``shipped`` with free ports, a run folder in ``tmp`` and the tiny field; and the
    ports its listeners must be on."""
    m = tomllib.loads(shipped.read_text())
    old_run = m.get("run_dir", "runs")
    run = tmp / "runs"
    ports: dict[int, int] = {}
    viz = m.get("services", {}).get("viz")
    if viz is not None and viz.get("serve"):
        defaults = VizConfig()
        viz.setdefault("grpc_port", defaults.grpc_port)
        viz.setdefault("web_port", defaults.web_port)

    def port(p: int) -> int:
        if p == 0:
            return 0  # a free one, or none (web_port)
        while p not in ports:
            new = free_port()
            if new not in ports.values():
                ports[p] = new
        return ports[p]

    def walk(x: Any, key: str = "") -> Any:
        if isinstance(x, dict):
            return {k: walk(v, k) for k, v in x.items()}
        if isinstance(x, list):
            return [walk(v) for v in x]
        if isinstance(x, int) and not isinstance(x, bool) and key.endswith("port"):
            return port(x)
        if isinstance(x, str):
            if x == old_run or x.startswith(f"{old_run}/"):
                return str(run) + x[len(old_run) :]
            if e := ENDPOINT.fullmatch(x):
                return f"{e[1]}:{port(int(e[2]))}"
        return x

    m = walk(m)
    m["field"] = str(TINY)
    path = tmp / shipped.name
    path.write_text(tomli_w.dumps(m))
    return path, set(ports.values())


def wait_exit(pids: list[int], timeout: float) -> list[int]:
    """Those of ``pids`` still running after ``timeout`` s, waited for on their pidfds
    (they are not this process's children)."""
    deadline = time.monotonic() + timeout
    left = []
    for pid in pids:
        try:
            fd = os.pidfd_open(pid)
        except ProcessLookupError:
            continue  # gone already
        try:
            ready, _, _ = select.select([fd], [], [], max(0.0, deadline - time.monotonic()))
            if not ready:
                left.append(pid)
        finally:
            os.close(fd)
    return left


@pytest.mark.parametrize("deployment", ["sim", "hil"])
def test_simulated_deployment_opens_sockets_on_loopback_only(
    deployment: str, procs: Procs, tmp_path: Path
) -> None:
    manifest, ports = private_copy(REPO / "deploy" / f"{deployment}.toml", tmp_path)
    loaded = load_manifest(manifest)
    services = {n for n in loaded.services if n in SERVICES}
    log = tmp_path / "up.log"
    up = procs.start("-m", "phenorover", "up", str(manifest), log=log)
    tree: dict[int, str] = {}
    try:
        session = zenoh.open(zenoh_config("client", [], loaded.zenoh.local_endpoints()))
        try:
            alive = wait_alive(session, services, timeout=90)
        finally:
            session.close()
        assert alive, f"not alive: {sorted(alive.missing)}; see {log}"
        # alive means serving: every listener is up by now (viz starts its servers
        # before it declares itself alive)
        socks = sockets(up.pid)
        tree = process_tree(up.pid)
        listening = {s.port for s in socks if s.state in ("LISTEN", "")}
        assert ports <= listening, f"configured ports not listening: {ports - listening}"
        beyond = [str(s) for s in socks if not s.loopback]
        assert not beyond, f"{deployment}: sockets beyond loopback:\n" + "\n".join(beyond)
    finally:
        up.send_signal(signal.SIGTERM)
        code = up.wait(timeout=20)
    assert code == 0, f"phenorover up exited {code}; see {log}"
    left = [f"{tree[p]} ({p})" for p in wait_exit(list(tree), timeout=10)]
    assert not left, f"outlived the launcher: {left}"
