"""Config of the FARO wire simulator (``[services.faro-sim]``)."""

from typing import Annotated

import msgspec

from common.messages.core import Positive
from services.scanner.sim.faults import FaroFaults


class FaroSimConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The FARO emulator behind an SLCAN serial link (``python -m
    services.scanner.sim.faro``, ``[services.faro-sim]``): it makes a pseudo-terminal
    and a symlink to it."""

    link: str = "runs/hil/faro-can"
    """The symlink to the pseudo-terminal, which the scanner service opens with
    ``backend = "can"``, ``interface = "slcan"``, ``channel = <link>``."""
    storage_dir: str = "runs/scanner-card"
    """Completed scans are rendered by the simulator into this folder (the scanner's
    card: give the scanner service the same folder)."""
    faults: FaroFaults = msgspec.field(default_factory=FaroFaults)
    """The emulator's faults (docs/faults.md)."""
    scan_time_s: Positive | None = None
    """Every scan's duration on the service clock (s); none: the profile's FARO scan
    time."""
    render_step_deg: Annotated[float, msgspec.Meta(gt=0, le=5)] = 0.36
    """The angular step the simulator renders the scans at (deg)."""
