from typing import Annotated, Literal

import msgspec

from common.messages.core import Positive
from services.scanner.sim.faults import FaroFaults


class ScannerConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The FARO scanner over its CAN automation interface."""

    backend: Literal["can", "sim"]  # required: no simulated default
    """``can`` (python-can) or ``sim`` (a FARO emulator on a virtual bus in this process;
    completed scans are rendered by the simulator into ``storage_dir``)."""
    interface: str = "socketcan"
    """python-can's interface: ``socketcan`` on the Jetson; ``slcan`` for a USB-CAN
    adapter, or the link that ``faro-sim`` makes."""
    channel: str = "can0"
    """The bus: ``can0``, or with ``slcan`` a serial device such as ``/dev/ttyACM0``."""
    bitrate: Annotated[int, msgspec.Meta(gt=0)] = 500_000
    """The CAN bus's bit rate."""
    tty_baudrate: Annotated[int, msgspec.Meta(gt=0)] = 115_200
    """``slcan`` only: the serial line's baud rate."""
    storage_dir: str = "runs/scanner-card"
    """Where the scanner's card is mounted: a scan's file is named here."""
    ack_timeout_s: Positive = 0.5
    """Each command waits this long for its ACK (wall time)."""
    retries: Annotated[int, msgspec.Meta(ge=0, le=10)] = 2
    """A command without an ACK is sent again this often."""
    stuck_timeout_s: Positive = 60.0
    """No progress for this long: the scan is reported stuck (service clock)."""
    status_timeout_s: Positive = 5.0
    """A device silent this long is an error (service clock)."""
    status_hz: Annotated[float, msgspec.Meta(gt=0, le=50)] = 5.0
    """How often status is published."""
    sim_faults: FaroFaults = msgspec.field(default_factory=FaroFaults)
    """Simulation only: injected FARO faults (docs/faults.md)."""
    sim_scan_time_s: Positive | None = None
    """Simulation only: a fixed scan duration (none: the profile's FARO scan time)."""
    render_step_deg: Annotated[float, msgspec.Meta(gt=0, le=5)] = 0.36
    """Simulation only: the angular step the simulated scan is rendered at."""
