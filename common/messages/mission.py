"""The mission supervisor's commands, state and events."""

from __future__ import annotations

import enum

import msgspec

from common.messages.core import FileName, Message, NonNegative
from common.messages.plan import PlanResult


class MissionStart(msgspec.Struct, frozen=True, tag=True):
    """Start a survey: ``plan`` (sent with the command: ``phenorover mission start
    --plan FILE`` reads it where it runs), ``plan_file`` (a plan.json path on the
    mission host, inside its run folder) or, when both are empty, a plan requested
    from the planner for ``field``, which is the deployment's field when empty and
    must name it otherwise. A plan split between robots is surveyed by each robot's
    mission in its share (the mission's ``share``)."""

    mission: FileName = ""
    field: str = ""
    plan_file: str = ""
    plan: PlanResult | None = None


class MissionPause(msgspec.Struct, frozen=True, tag=True):
    pass


class MissionResume(msgspec.Struct, frozen=True, tag=True):
    pass


class MissionAbort(msgspec.Struct, frozen=True, tag=True):
    pass


class MissionStatusQuery(msgspec.Struct, frozen=True, tag=True):
    pass


MissionCommand = MissionStart | MissionPause | MissionResume | MissionAbort | MissionStatusQuery


class MissionPhase(enum.StrEnum):
    IDLE = "idle"
    PLANNING = "planning"
    DRIVING = "driving"
    SETTLING = "settling"
    SCANNING = "scanning"
    RETURNING = "returning"
    # at the Origin, waiting for a battery swap (common.battery)
    SWAPPING = "swapping"
    PAUSED = "paused"
    DONE = "done"
    ABORTED = "aborted"
    FAILED = "failed"


# the phases a mission ends in
FINAL_PHASES = (MissionPhase.DONE, MissionPhase.ABORTED, MissionPhase.FAILED)

# MissionState.detail of a survey that is done while its scans are being registered
# (a child process of the mission service); another detail once registration ends
REGISTERING = "registering"
# the detail while the registered cloud's per-plot traits are computed (the next child
# process, once registration succeeded and the mission asks for traits)
COMPUTING_TRAITS = "computing traits"
# the details of a mission whose outputs are still being made after the survey
POST_PROCESSING = (REGISTERING, COMPUTING_TRAITS)


class MissionState(Message, frozen=True, kw_only=True):
    """``distance_m``: metres driven since the survey (or its resumption) began,
    measured: the pose estimate's speed (wheel odometry fused with GNSS) over time.
    ``planned_m``: the plan's tour length (m), planned, not measured."""

    mission: str
    phase: MissionPhase
    scans_done: int = 0
    scans_failed: int = 0
    scans_total: int = 0
    current_scan: int = 0
    distance_m: NonNegative = 0.0
    detail: str = ""
    planned_m: NonNegative = 0.0

    @property
    def in_progress(self) -> bool:
        """Whether this is of a mission still going (a resumed one included)."""
        return bool(self.mission) and self.phase not in (*FINAL_PHASES, MissionPhase.IDLE)


class MissionEvent(Message, frozen=True, kw_only=True):
    """Something the operator should know: ``level`` is info, warning or error."""

    mission: str
    level: str
    text: str


class LaneQuery(msgspec.Struct, frozen=True, kw_only=True):
    """What lane segments do you hold and want? (asked by the other robots' missions)."""

    robot: str  # the asker's namespace, for the answerer's log


class LaneClaims(Message, frozen=True, kw_only=True):
    """A robot's lane reservations (:mod:`services.mission.lanes`): the segments
    (:mod:`common.lanes`) it ``held`` and those it ``wanted`` when it answered, and
    those it is ``waiting`` for (held by another robot)."""

    robot: str
    held: list[str] = msgspec.field(default_factory=list)
    wanted: list[str] = msgspec.field(default_factory=list)
    waiting: list[str] = msgspec.field(default_factory=list)
