from typing import Annotated, Literal

import msgspec

from services.gnss.compass import CompassConfig
from services.gnss.rtk_model import RtkModelConfig


class AntennaConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """One rover receiver. ``port``/``baud`` for ``nmea-serial``; ``host``/``tcp_port``
    for ``nmea-tcp`` (Emlid Reach M2 "TCP server" NMEA output)."""

    id: Annotated[int, msgspec.Meta(ge=1, le=2)]
    port: str = ""
    baud: Annotated[int, msgspec.Meta(gt=0)] = 115200
    host: str = ""
    tcp_port: Annotated[int, msgspec.Meta(ge=0, le=65535)] = 9001


def _antennas() -> list[AntennaConfig]:
    return [AntennaConfig(id=1, port="/dev/ttyUSB0"), AntennaConfig(id=2, port="/dev/ttyUSB1")]


class GnssConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The two rover receivers and the GNSS compass. ``antennas`` says how to reach
    each receiver; where its antenna sits on the robot is the robot description's
    (:mod:`common.robot`), antenna ``id`` N being its Nth ``[[antennas]]``.

    ``backend``: ``sim`` (NMEA made from the simulator's antenna truth through ``rtk``),
    ``nmea-serial`` or ``nmea-tcp``. ``fallback_sigma_m`` is the 1-sigma horizontal
    error assumed per fix type when the receiver sends no GST sentence.
    """

    backend: Literal["sim", "nmea-serial", "nmea-tcp"]  # required: no simulated default
    antennas: list[AntennaConfig] = msgspec.field(default_factory=_antennas)
    compass: CompassConfig = msgspec.field(default_factory=CompassConfig)
    rtk: RtkModelConfig = msgspec.field(default_factory=RtkModelConfig)
    seed: int = 1
    fallback_sigma_m: dict[str, float] = msgspec.field(
        default_factory=lambda: {"FIX": 0.014, "FLOAT": 0.25, "DGPS": 0.5, "SINGLE": 1.2}
    )
