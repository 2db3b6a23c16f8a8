from typing import Annotated

import msgspec

from common.messages.scan import ScanProfile

Pos = Annotated[float, msgspec.Meta(gt=0)]


def _profile() -> ScanProfile:
    # 1/8 resolution at 2x quality: about a minute on a Focus S70 (scan_id is set per step)
    return ScanProfile(scan_id=1, resolution=8, quality=2)


class MissionConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The survey supervisor. Times are on the service's clock (sim time in simulation).

    ``settle_s``: how long the robot must be still (|v| < ``still_speed``, |w| <
    ``still_turn``) and localized before a scan starts. ``scan_retries``: further
    attempts after a scanner error before the location is marked failed.
    ``blocked_retries``: route attempts after navigation reports blocked before the
    location is skipped. ``resume``: pick up an unfinished mission found in the run
    folder when the service starts. ``register_on_done``: register the scans (``python
    -m services.register RUN_DIR``, a child process at low priority) once the mission
    is done.
    """

    profile: ScanProfile = msgspec.field(default_factory=_profile)
    settle_s: Pos = 2.0
    still_speed: Pos = 0.01
    still_turn: Pos = 0.01
    scan_retries: Annotated[int, msgspec.Meta(ge=0, le=10)] = 2
    scan_timeout_s: Pos = 1800.0
    blocked_retries: Annotated[int, msgspec.Meta(ge=0, le=10)] = 1
    route_timeout_s: Pos = 1800.0
    plan_timeout_s: Pos = 300.0
    return_to_origin: bool = True
    resume: bool = True
    register_on_done: bool = True
