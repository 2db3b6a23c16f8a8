"""What the route follower (:mod:`services.nav.follower`) works in: its phases, the
command it returns each step, and the step's inputs its phases share. Pure."""

from __future__ import annotations

import dataclasses
import enum

from common.messages.nav import Leg, NavState


class Phase(enum.Enum):
    ALIGN = "align"
    DRIVE = "drive"
    FINAL = "final"
    FINE = "fine"
    BACKUP = "backup"


@dataclasses.dataclass
class Command:
    v: float
    w: float
    state: NavState
    leg: int
    distance_to_go: float
    cross_track: float
    heading_error: float
    event: str = ""  # set once when the route ends: arrived, blocked
    detail: str = ""  # with an event: how it ended, for the log


@dataclasses.dataclass(frozen=True)
class Tick:
    """One step: its time ``t`` and ``dt`` since the last (s), the pose estimate,
    whether an obstacle is ahead, the current leg, its heading, and the cross-track,
    heading error and distance to go every command of the step reports."""

    t: float
    dt: float
    x: float
    y: float
    yaw: float
    obstacle: bool
    leg: Leg
    heading: float
    xte: float
    herr: float
    togo: float
