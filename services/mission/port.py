"""What a survey lends the parts it runs (:mod:`.scanning`'s scans and :mod:`.standing`'s
wait for the robot to stand still): its clock, its calls, its feeds and its log.
:class:`services.mission.survey.Survey` is the one that has them; the parts see only
this, so neither imports the survey that imports them."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, TypeVar

from common.keys import Rpc
from common.messages.nav import PoseEstimate
from common.messages.scan import ScannerStatus
from common.missionlog import Step
from common.service import Context
from common.transport import Latest
from services.mission.config import MissionConfig
from services.mission.log import MissionLog

Q = TypeVar("Q")
R = TypeVar("R")


class SurveyPort(Protocol):
    ctx: Context
    cfg: MissionConfig
    log: MissionLog
    mission: str
    event: Callable[[str, str], None]
    pose: Latest[PoseEstimate]
    scanner: Latest[ScannerStatus]

    def now(self) -> int: ...

    def wait(self, seconds: float) -> int: ...

    def call(self, rpc: Rpc[Q, R], req: Q) -> R: ...

    def pose_age_s(self) -> float: ...

    def collect(self, poses: list[PoseEstimate] | None) -> None: ...

    def collected(self) -> list[PoseEstimate]: ...

    def off_by(self, step: Step, x: float, y: float) -> float: ...

    def settle(self) -> PoseEstimate | None: ...
