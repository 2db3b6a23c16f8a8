"""A classic CAN frame as an SLCAN line, both ways (Lawicel: ``tiiildd..`` standard,
``Tiiiiiiiildd..`` extended, ``r``/``R`` remote; ids and data in hex). Pure but for
the receive time a parsed frame is stamped with."""

from __future__ import annotations

import time

import can

_HEX = frozenset("0123456789abcdefABCDEF")


def is_hex(s: str) -> bool:
    return all(c in _HEX for c in s)


def frame_line(msg: can.Message) -> bytes:
    """``msg``'s line, CR-terminated."""
    kind = "r" if msg.is_remote_frame else "t"
    kind = kind.upper() if msg.is_extended_id else kind
    ident = f"{msg.arbitration_id:08X}" if msg.is_extended_id else f"{msg.arbitration_id:03X}"
    data = "" if msg.is_remote_frame else bytes(msg.data[: msg.dlc]).hex().upper()
    return f"{kind}{ident}{msg.dlc:d}{data}\r".encode()


def parse_frame(line: str, channel: str) -> can.Message | str:
    """The frame of a ``t``/``T``/``r``/``R`` line (without its CR), stamped now and
    on ``channel``; or what is wrong with it, in a few words."""
    ext, remote = line[0] in "TR", line[0] in "rR"
    n = 8 if ext else 3
    ident, dlc, data = line[1 : 1 + n], line[1 + n : 2 + n], line[2 + n :]
    if len(ident) != n or not is_hex(ident) or len(dlc) != 1 or dlc not in "012345678":
        return "frame id or length malformed"
    arb, size = int(ident, 16), int(dlc)
    if len(data) != (0 if remote else 2 * size) or not is_hex(data):
        return f"frame data does not match its length {size}"
    if arb > (0x1FFFFFFF if ext else 0x7FF):
        return f"frame id {ident} out of range"
    return can.Message(
        timestamp=time.time(),
        arbitration_id=arb,
        is_extended_id=ext,
        is_remote_frame=remote,
        dlc=size,
        data=b"" if remote else bytes.fromhex(data),
        channel=channel,
    )
