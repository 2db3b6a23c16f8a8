from typing import Annotated, Literal

import msgspec

from common.messages.core import Positive, Seed
from common.messages.gnss import FixType
from services.gnss.compass import CompassConfig
from services.gnss.rtk_model import RtkModelConfig


class AntennaConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """How to reach one rover receiver."""

    id: Annotated[int, msgspec.Meta(ge=1, le=2)]
    """1 or 2: the robot description's first or second ``[[antennas]]``."""
    port: str = ""
    """``nmea-serial``: the serial port."""
    baud: Annotated[int, msgspec.Meta(gt=0)] = 115200
    """``nmea-serial``: its baud rate."""
    host: str = ""
    """``nmea-tcp``: the receiver's address (Emlid Reach M2 "TCP server" NMEA output)."""
    tcp_port: Annotated[int, msgspec.Meta(ge=0, le=65535)] = 9001
    """``nmea-tcp``: its port."""


def _antennas() -> list[AntennaConfig]:
    return [AntennaConfig(id=1, port="/dev/ttyUSB0"), AntennaConfig(id=2, port="/dev/ttyUSB1")]


class GnssConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The two rover receivers and the GNSS compass. Where each antenna sits on the
    robot is the robot description's (:mod:`common.robot`)."""

    backend: Literal["sim", "nmea-serial", "nmea-tcp"]  # required: no simulated default
    """``nmea-serial``, ``nmea-tcp`` (Emlid Reach M2 "TCP server" NMEA output,
    reconnecting) or ``sim`` (NMEA made from the simulator's antenna truth through
    ``rtk``)."""
    antennas: list[AntennaConfig] = msgspec.field(default_factory=_antennas)
    """How to reach each rover: two on ``/dev/ttyUSB0``, ``/dev/ttyUSB1`` by default."""
    compass: CompassConfig = msgspec.field(default_factory=CompassConfig)
    """The GNSS compass's check of the antennas' separation."""
    rtk: RtkModelConfig = msgspec.field(default_factory=RtkModelConfig)
    """The ``sim`` backend's RTK error model (docs/simulation.md)."""
    seed: Seed = 1
    """The ``sim`` backend's noise seed."""
    fallback_sigma_m: dict[str, Positive] = msgspec.field(
        default_factory=lambda: {"FIX": 0.014, "FLOAT": 0.25, "DGPS": 0.5, "SINGLE": 1.2}
    )
    """The 1-sigma horizontal error assumed per fix type when a receiver sends no GST
    sentence (m), keyed by fix type (``FixType``'s names); a fix type left out is taken
    at 10 m."""

    def __post_init__(self) -> None:
        unknown = sorted(set(self.fallback_sigma_m) - set(FixType.__members__))
        if unknown:
            raise ValueError(
                f"fallback_sigma_m: {', '.join(unknown)} is no fix type "
                f"({', '.join(FixType.__members__)})"
            )
