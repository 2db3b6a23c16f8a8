"""The terrestrial laser scanner (FARO Focus S70 over the CAN automation interface)."""

from __future__ import annotations

import enum
from typing import Annotated

import msgspec

from common.messages.core import Angle, FileName, Message, Probability


class ScanProfile(msgspec.Struct, frozen=True, kw_only=True):
    """A scan's settings."""

    scan_id: Annotated[int, msgspec.Meta(ge=1, le=65535)]
    """The number that names the scan's file (``Scan_NNNNN``); the mission sets it per
    location."""
    resolution: Annotated[int, msgspec.Meta(ge=1, le=32)] = 4
    """FARO's resolution as its fraction's denominator (1/4 -> 4)."""
    quality: Annotated[int, msgspec.Meta(ge=1, le=8)] = 4
    """FARO's quality, its noise-compression factor."""


class StartScan(msgspec.Struct, frozen=True, tag=True):
    """Start a scan. ``project`` is the folder on the scanner's storage it goes to, as
    a FARO keeps scans by project; the mission passes its own name, so the scans of
    two missions never share a file even though both number theirs from 1."""

    profile: ScanProfile
    project: FileName = ""


class PauseScan(msgspec.Struct, frozen=True, tag=True):
    pass


class StopScan(msgspec.Struct, frozen=True, tag=True):
    pass


ScannerCommand = StartScan | PauseScan | StopScan


class ScannerReply(Message, frozen=True, kw_only=True):
    ok: bool
    reason: str = ""


class ScannerState(enum.StrEnum):
    IDLE = "idle"
    SCANNING = "scanning"
    PAUSED = "paused"
    DONE = "done"
    ERROR = "error"


class ScannerStatus(Message, frozen=True, kw_only=True):
    """Scanner state. ``progress`` 0..1; when DONE, ``file`` is the scan's path on the
    scanner host and ``pitch``/``roll`` the inclinometer's reading (radians)."""

    state: ScannerState
    scan_id: int = 0
    progress: Probability = 0.0
    error: str = ""
    file: str = ""
    pitch: Angle = 0.0
    roll: Angle = 0.0
