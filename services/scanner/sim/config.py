"""Config of the FARO wire simulator (``[services.faro-sim]``)."""

from typing import Annotated

import msgspec

from common.messages.core import Positive
from services.scanner.sim.faults import FaroFaults


class FaroSimConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The FARO emulator behind an SLCAN serial link (``python -m
    services.scanner.sim.faro``, ``[services.faro-sim]``): it makes a pseudo-terminal
    and the symlink ``link`` to it, which the scanner service opens with
    ``backend = "can"``, ``interface = "slcan"``, ``channel = <link>``. Completed scans
    are rendered by the simulator into ``storage_dir`` (the scanner's card: give the
    scanner service the same folder). ``scan_time_s``: every scan's duration on the
    service clock (default: the profile's FARO scan time)."""

    link: str = "runs/hil/faro-can"
    storage_dir: str = "runs/scanner-card"
    faults: FaroFaults = msgspec.field(default_factory=FaroFaults)
    scan_time_s: Positive | None = None
    render_step_deg: Annotated[float, msgspec.Meta(gt=0, le=5)] = 0.36
