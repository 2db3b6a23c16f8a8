from typing import Annotated, Literal

import msgspec

from common.messages.core import Positive
from services.scanner.sim.faults import FaroFaults


class ScannerConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The FARO scanner over its CAN automation interface.

    ``backend``: ``can`` (python-can with ``interface``/``channel``/``bitrate``:
    ``socketcan``/``can0`` on the Jetson; ``slcan`` with a serial ``channel`` such as
    ``/dev/ttyACM0`` for a USB-CAN adapter, or the link that ``faro-sim`` makes, at
    ``tty_baudrate``) or ``sim`` (a FARO emulator on a virtual bus
    in this process; completed scans are rendered by the simulator into
    ``storage_dir``). ``stuck_timeout_s`` and ``status_timeout_s`` run on the service's
    clock (sim time in simulation), ``ack_timeout_s`` on wall time.
    """

    backend: Literal["can", "sim"]  # required: no simulated default
    interface: str = "socketcan"
    channel: str = "can0"
    bitrate: Annotated[int, msgspec.Meta(gt=0)] = 500_000
    tty_baudrate: Annotated[int, msgspec.Meta(gt=0)] = 115_200  # slcan only
    storage_dir: str = "runs/scanner-card"
    ack_timeout_s: Positive = 0.5
    retries: Annotated[int, msgspec.Meta(ge=0, le=10)] = 2
    stuck_timeout_s: Positive = 60.0
    status_timeout_s: Positive = 5.0
    status_hz: Annotated[float, msgspec.Meta(gt=0, le=50)] = 5.0
    # simulation only
    sim_faults: FaroFaults = msgspec.field(default_factory=FaroFaults)
    sim_scan_time_s: Positive | None = None  # default: the profile's FARO scan time
    render_step_deg: Annotated[float, msgspec.Meta(gt=0, le=5)] = 0.36
