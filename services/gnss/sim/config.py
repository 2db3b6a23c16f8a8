"""Config of the Reach M2 wire simulator (``[services.reach-sim]``)."""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec

from common.messages.core import NonNegative, Seed
from services.gnss.rtk_model import RtkModelConfig


class ReachOutput(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Where one simulated receiver sends its NMEA."""

    id: Annotated[int, msgspec.Meta(ge=1, le=2)]
    """The receiver's antenna."""
    tcp_port: Annotated[int, msgspec.Meta(ge=0, le=65535)] | None = None
    """A TCP server (a Reach's "TCP server" position output); 0: a free port, logged;
    none: no server."""
    pty: str = ""
    """A pseudo-terminal in raw mode, with a symlink at this path for the gnss
    ``nmea-serial`` backend to open as its ``port``; empty: none."""


class ReachFaults(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Faults of the wires, at sim times (seconds of the truth stream's stamps), for
    tests; the same faults can be triggered at run time by signals (SIGUSR1: drop the
    TCP links, SIGUSR2: garbage on the serial lines)."""

    drop_links_at_s: list[NonNegative] = msgspec.field(default_factory=list)
    """At these times every TCP client of every receiver is disconnected (the
    receiver's Wi-Fi link drops; its server keeps listening)."""
    garbage_at_s: list[NonNegative] = msgspec.field(default_factory=list)
    """At these times ``garbage`` is written into every serial line between two epochs
    (line noise)."""
    garbage: str = "\x00\xff\xfe~#noise$GNGGA,12,,*ZZ\r\n$$$\x7f\r\n"
    """The line noise written."""


def _outputs() -> list[ReachOutput]:
    return [ReachOutput(id=1, tcp_port=9001), ReachOutput(id=2, tcp_port=9002)]


class ReachSimConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Two simulated Emlid Reach M2 rovers fed by the simulator's antenna truth."""

    host: str = "127.0.0.1"
    """The address the TCP servers listen on (loopback unless a robot on the network
    must reach it)."""
    outputs: list[ReachOutput] = msgspec.field(default_factory=_outputs)
    """Where each receiver sends its NMEA."""
    talker: Literal["GN", "GP"] = "GN"
    """The NMEA talker: ``GN`` (multi-constellation, the Reach default) or ``GP``."""
    rtk: RtkModelConfig = msgspec.field(default_factory=RtkModelConfig)
    """The RTK error model, as ``[services.gnss.rtk]`` (the same values and ``seed``
    give the same noise as the gnss ``sim`` backend)."""
    seed: Seed = 1
    """The noise seed, as ``[services.gnss]``'s."""
    faults: ReachFaults = msgspec.field(default_factory=ReachFaults)
    """Faults of the wires, for tests."""
