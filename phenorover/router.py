"""This machine's Zenoh router as the launcher opens it: its configuration from the
manifest (endpoints, TLS, access control admitting the ROS 2 domain the base speaks)
and its log, from which the access-control denials are picked out."""

from __future__ import annotations

import os
import sys
import threading
import time

import zenoh

from common.acl import router_acl
from common.acl_log import LOG_TARGET, DenialLog
from common.config import Manifest, decode_section, zenoh_config
from services.base.config import BaseConfig

# the router's access-control verdicts: Zenoh logs them at trace level, allowed and
# denied alike; :class:`DenialLog` keeps the denials
ACL_LOG_FILTER = f"error,{LOG_TARGET}=trace"


def ros2_domains(manifest: Manifest) -> list[int]:
    """The ROS 2 domains this machine's services speak over rmw_zenoh: the base's,
    when it drives a ROS 2 base through rmw_zenoh (its section was validated)."""
    section = manifest.services.get("base")
    if section is None:
        return []
    cfg = decode_section(section, BaseConfig, "[services.base]")
    return [cfg.ros2_domain] if cfg.backend == "ros2" and cfg.ros2_layout == "rmw_zenoh" else []


def router_config(manifest: Manifest) -> zenoh.Config:
    """This machine's router: its endpoints, TLS and access control from the manifest
    (local links admitted to the ROS 2 domain its base speaks, :func:`ros2_domains`)."""
    zs = manifest.zenoh
    acl = router_acl(zs.access, ros2_domains(manifest)) if zs.access is not None else None
    return zenoh_config("router", zs.listen, zs.connect, zs.tls, access_control=acl)


class StdoutFilter:
    """Zenoh writes its log to file descriptor 1. While this is open, fd 1 is a pipe
    read by a thread that hands each line to a :class:`DenialLog` and passes every
    other line on to the real stdout; :meth:`close` puts the real stdout back."""

    def __init__(self, denials: DenialLog) -> None:
        sys.stdout.flush()
        self._denials = denials
        self._real = os.dup(1)
        read, write = os.pipe()
        os.dup2(write, 1)
        os.close(write)  # fd 1 is now the pipe's only writer: EOF once it is put back
        self._thread = threading.Thread(target=self._pump, args=(read,), daemon=True)
        self._thread.start()

    def _pump(self, read: int) -> None:
        with os.fdopen(read, "rb") as pipe, open(self._real, "wb", closefd=False) as out:
            for raw in pipe:
                if not self._denials.feed(raw.decode(errors="replace"), time.monotonic()):
                    out.write(raw)
                    out.flush()

    def close(self) -> None:
        sys.stdout.flush()
        os.dup2(self._real, 1)
        self._thread.join(timeout=2.0)
        os.close(self._real)
