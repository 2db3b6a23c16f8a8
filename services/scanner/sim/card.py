"""The emulated scanner's memory card: a completed scan is rendered by the simulator
(``rpc/sim/render``) into the storage folder, as a real scan lands on the FARO's card.

One implementation for both emulated scanners: the in-process one of the ``sim``
backend (:class:`services.scanner.sim.device.SimDevice`) and the one across a serial CAN
link (:mod:`services.scanner.sim.faro`).
"""

from __future__ import annotations

import math
from pathlib import Path

import can

from common import keys
from common.messages.sim import RenderRequest
from common.service import Context
from services.scanner.can_codec import ScanProfile
from services.scanner.device import scan_path
from services.scanner.sim.emulator import FaroEmulator, FaroFaults, default_scan_duration_s

# a scan can take minutes to render at fine steps on a small machine
RENDER_TIMEOUT_S = 300.0


class ScanDuration:
    """The emulator's scan time: ``fixed_s`` for every scan, or the profile's FARO
    time when ``None``."""

    def __init__(self, fixed_s: float | None) -> None:
        self._fixed_s = fixed_s

    def __call__(self, profile: ScanProfile) -> float:
        return default_scan_duration_s(profile) if self._fixed_s is None else self._fixed_s


class RenderedCard:
    """``store`` is the emulator's ``on_scan_complete``: it blocks until the simulator
    has written the scan (raising when it cannot, which fails the scan), then keeps the
    inclinometer reading (degrees) that ``inclination`` hands to the next DONE.

    ``project``: the scan project the next scans go to (set by whoever knows it)."""

    def __init__(self, ctx: Context, storage_dir: str, step_deg: float) -> None:
        self._ctx, self._storage_dir, self._step_deg = ctx, storage_dir, step_deg
        self.project = ""
        self._inclination = (0.0, 0.0)
        Path(storage_dir).mkdir(parents=True, exist_ok=True)

    def inclination(self) -> tuple[float, float]:
        return self._inclination

    def store(self, scan_id: int, profile: ScanProfile) -> None:
        path = scan_path(self._storage_dir, scan_id, self.project)
        path.parent.mkdir(parents=True, exist_ok=True)
        req = RenderRequest(scan_id=scan_id, path=str(path.resolve()), step_deg=self._step_deg)
        rep = self._ctx.bus.call(keys.SIM_RENDER, req, timeout=RENDER_TIMEOUT_S)
        self._inclination = (math.degrees(rep.pitch), math.degrees(rep.roll))
        self._ctx.log.info(
            "scan %d stored: %s (%d points, rendered in %.1f s)",
            scan_id,
            rep.path,
            rep.points,
            rep.render_s,
        )


def emulate(
    ctx: Context,
    bus: can.BusABC,
    card: RenderedCard,
    faults: FaroFaults,
    scan_time_s: float | None,
    timed: bool = True,
) -> FaroEmulator:
    """The FARO emulator answering on ``bus``, on the service's clock, its completed scans
    stored on ``card`` (not started); ``timed`` False: advanced by its owner's ticks."""
    return FaroEmulator(
        bus,
        timed=timed,
        now=lambda: ctx.clock.now_ns() / 1e9,
        scan_duration_s=ScanDuration(scan_time_s),
        faults=faults,
        on_scan_complete=card.store,
        inclination_deg=card.inclination,
    )
