"""Typed CAN frames of the FARO automation interface, encoded through ``faro.dbc``.

The DBC file is the single place where identifiers, lengths and scalings live (FARO
does not publish them; users edit the file for their adapter). This module maps its
messages to typed Structs and back, and turns every malformed frame into one
:class:`CanDecodeError` naming the frame id and the reason.
"""

from __future__ import annotations

import functools
from enum import IntEnum
from pathlib import Path
from typing import Annotated, Any

import can
import cantools
import msgspec
from cantools.database.can import Database
from cantools.database.can import Message as DbcMessage

DBC_PATH = Path(__file__).with_name("faro.dbc")


class CanDecodeError(ValueError):
    """A received frame that is not a valid FARO frame (the message says which and why)."""


class CanEncodeError(ValueError):
    """A frame whose fields do not fit the DBC (out of range, wrong type)."""


class ScanState(IntEnum):
    IDLE = 0
    SCANNING = 1
    PAUSED = 2
    DONE = 3
    ERROR = 4


class AckResult(IntEnum):
    OK = 0
    BUSY = 1
    INVALID_PARAMETER = 2
    NOT_SCANNING = 3
    ERROR = 4


#: Resolution divisors for ``ScanProfile.resolution_index`` (1/1 .. 1/32).
RESOLUTION_DIVISORS: tuple[int, ...] = (1, 2, 4, 5, 8, 10, 16, 20, 32)


class ScanProfile(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Scan settings: resolution 1/``RESOLUTION_DIVISORS[resolution_index]`` of full
    resolution and quality (noise compression) 1x..8x."""

    resolution_index: Annotated[int, msgspec.Meta(ge=0, le=8)] = 2
    quality: Annotated[int, msgspec.Meta(ge=1, le=8)] = 4


class InitiateScan(msgspec.Struct, frozen=True, kw_only=True):
    scan_id: int
    profile: ScanProfile = ScanProfile()


class RecordPause(msgspec.Struct, frozen=True, kw_only=True):
    """``pause=True`` pauses the scan in progress, ``False`` resumes it."""

    pause: bool


class EndScan(msgspec.Struct, frozen=True, kw_only=True):
    scan_id: int


class Ack(msgspec.Struct, frozen=True, kw_only=True):
    """Acknowledgement of the command whose CAN id is ``command_id``."""

    command_id: int
    result: AckResult = AckResult.OK


class Status(msgspec.Struct, frozen=True, kw_only=True):
    state: ScanState
    progress_pct: int = 0
    error_code: int = 0
    scan_id: int = 0


class Inclinometer(msgspec.Struct, frozen=True, kw_only=True):
    """Compensator reading in degrees (REP-103 signs) at the end of scan ``scan_id``."""

    pitch_deg: float
    roll_deg: float
    scan_id: int = 0


Frame = InitiateScan | RecordPause | EndScan | Ack | Status | Inclinometer

# DBC message name and the signals each must have (the rest of the layout is free).
_LAYOUT: dict[type[Any], tuple[str, tuple[str, ...]]] = {
    InitiateScan: ("InitiateScanOperation", ("ScanId", "ResolutionIndex", "Quality")),
    RecordPause: ("RecordPause", ("Action",)),
    EndScan: ("EndScanOperation", ("ScanId",)),
    Ack: ("Ack", ("CommandId", "Result")),
    Status: ("Status", ("State", "Progress", "ErrorCode", "ScanId")),
    Inclinometer: ("Inclinometer", ("Pitch", "Roll", "ScanId")),
}


def _signals(frame: Frame) -> dict[str, float]:
    match frame:
        case InitiateScan(scan_id=sid, profile=p):
            return {"ScanId": sid, "ResolutionIndex": p.resolution_index, "Quality": p.quality}
        case RecordPause(pause=pause):
            return {"Action": int(pause)}
        case EndScan(scan_id=sid):
            return {"ScanId": sid}
        case Ack(command_id=cid, result=res):
            return {"CommandId": cid, "Result": int(res)}
        case Status():
            return {
                "State": int(frame.state),
                "Progress": frame.progress_pct,
                "ErrorCode": frame.error_code,
                "ScanId": frame.scan_id,
            }
        case Inclinometer():
            return {"Pitch": frame.pitch_deg, "Roll": frame.roll_deg, "ScanId": frame.scan_id}
    raise CanEncodeError(f"not a FARO frame: {frame!r}")


def _build(kind: type[Any], s: dict[str, Any]) -> Frame:
    if kind is InitiateScan:
        profile = ScanProfile(resolution_index=int(s["ResolutionIndex"]), quality=int(s["Quality"]))
        return InitiateScan(scan_id=int(s["ScanId"]), profile=profile)
    if kind is RecordPause:
        return RecordPause(pause=bool(s["Action"]))
    if kind is EndScan:
        return EndScan(scan_id=int(s["ScanId"]))
    if kind is Ack:
        return Ack(command_id=int(s["CommandId"]), result=AckResult(int(s["Result"])))
    if kind is Status:
        return Status(
            state=ScanState(int(s["State"])),
            progress_pct=int(s["Progress"]),
            error_code=int(s["ErrorCode"]),
            scan_id=int(s["ScanId"]),
        )
    return Inclinometer(pitch_deg=s["Pitch"], roll_deg=s["Roll"], scan_id=int(s["ScanId"]))


class FaroCodec:
    """Encoder/decoder for one DBC file; load once and share (it is immutable).

    Raises ValueError on load when the DBC lacks a message or signal this code needs,
    or uses extended (29-bit) ids: the paper's adapter speaks CAN 2.0A.
    """

    def __init__(self, dbc_path: str | Path = DBC_PATH) -> None:
        db = cantools.database.load_file(str(dbc_path), database_format="dbc")
        assert isinstance(db, Database)
        self._by_kind: dict[type[Any], DbcMessage] = {}
        for kind, (name, signals) in _LAYOUT.items():
            try:
                msg = db.get_message_by_name(name)
            except KeyError:
                raise ValueError(f"{dbc_path}: no message {name}") from None
            missing = set(signals) - {s.name for s in msg.signals}
            if missing:
                raise ValueError(f"{dbc_path}: message {name} lacks signals {sorted(missing)}")
            if msg.is_extended_frame:
                raise ValueError(f"{dbc_path}: message {name} has an extended id")
            self._by_kind[kind] = msg
        self._by_id = {m.frame_id: (k, m) for k, m in self._by_kind.items()}

    def frame_id(self, kind: type[Frame]) -> int:
        """The 11-bit CAN id of frames of type ``kind``."""
        return int(self._by_kind[kind].frame_id)

    def encode(self, frame: Frame) -> can.Message:
        """The CAN frame for ``frame``. Raises :class:`CanEncodeError` when a field does
        not fit its signal."""
        msg = self._by_kind.get(type(frame))
        if msg is None:
            raise CanEncodeError(f"not a FARO frame: {frame!r}")
        try:
            data = msg.encode(_signals(frame), strict=True)
        except (cantools.database.EncodeError, ValueError, TypeError, KeyError) as e:
            raise CanEncodeError(f"{msg.name} (0x{msg.frame_id:03X}): {e}") from None
        return can.Message(arbitration_id=msg.frame_id, is_extended_id=False, data=data)

    def decode(self, message: can.Message) -> Frame:
        """The typed frame in ``message``. Raises :class:`CanDecodeError` for error or
        remote frames, extended ids, unknown ids, a wrong length, or a signal outside
        its DBC range or value table."""
        fid = message.arbitration_id
        where = f"CAN frame 0x{fid:03X}"
        if message.is_error_frame:
            raise CanDecodeError(f"{where}: is a bus error frame")
        if message.is_remote_frame:
            raise CanDecodeError(f"{where}: is a remote frame")
        if message.is_extended_id:
            raise CanDecodeError(f"CAN frame 0x{fid:08X}: extended id, FARO uses 11-bit ids")
        entry = self._by_id.get(fid)
        if entry is None:
            raise CanDecodeError(f"{where}: unknown id")
        kind, msg = entry
        data = bytes(message.data)
        if len(data) != msg.length or message.dlc != msg.length:
            raise CanDecodeError(f"{where} ({msg.name}): DLC {message.dlc}, expected {msg.length}")
        try:
            values = msg.decode(data, decode_choices=False, scaling=True)
        except cantools.database.DecodeError as e:
            raise CanDecodeError(f"{where} ({msg.name}): {e}") from None
        assert isinstance(values, dict)
        for sig in msg.signals:
            v = values[sig.name]
            assert isinstance(v, int | float)
            lo, hi = sig.minimum, sig.maximum
            # Half a scale step of slack: scaled values are float products.
            eps = abs(sig.scale) / 2
            if (lo is not None and v < lo - eps) or (hi is not None and v > hi + eps):
                raise CanDecodeError(f"{where} ({msg.name}): {sig.name}={v} outside [{lo}, {hi}]")
        try:
            return _build(kind, values)
        except (ValueError, msgspec.ValidationError) as e:
            raise CanDecodeError(f"{where} ({msg.name}): {e}") from None


@functools.cache
def default_codec() -> FaroCodec:
    """The codec for the packaged ``faro.dbc``, loaded once per process."""
    return FaroCodec()
