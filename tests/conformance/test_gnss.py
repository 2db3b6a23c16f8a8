"""The GNSS contract, run against every receiver backend of the gnss service: ``sim``
(NMEA made from the simulator's antenna truth in the service), ``nmea-tcp`` and
``nmea-serial`` (the simulated Reach M2s of ``services.gnss.sim.reach`` on a TCP
server and on a pseudo-terminal, read as a real receiver is).

Whatever the backend, antenna truth in gives per-antenna fixes with the receiver's fix
quality and its own precision as covariance, a compass heading from the two antennas,
and sentences that do not parse are dropped, counted and logged once. The RTK model is
held in its state, so every change of quality is a fault's. The test sends one epoch of
truth at a time and waits for what it brings."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator, Sized
from pathlib import Path
from typing import cast

import numpy as np
import pytest

from common import keys
from common.clock import NS
from common.messages.gnss import FixType, GnssHeading, NavSatFix
from common.messages.sim import SimAntennas
from common.streams import Publisher
from common.transport import Bus
from services.gnss.config import AntennaConfig, GnssConfig
from services.gnss.nmea import Gga
from services.gnss.nmea_format import format_gga
from services.gnss.receiver import SimReceiver
from services.gnss.rtk_model import STATES, RtkModelConfig
from services.gnss.service import GnssService
from services.gnss.sim.config import ReachOutput, ReachSimConfig
from services.gnss.sim.reach import ReachSim
from tests.conformance.conftest import Running, context, sessions
from tests.conftest import Record, record

BACKENDS = ["sim", "nmea-tcp", "nmea-serial"]
HELD = RtkModelConfig(rates_per_s=[[0.0] * len(STATES) for _ in STATES])
YAW = math.radians(30.0)
# the two antennas 0.95 m apart along base_link's x, heading YAW, at (10, 5) in the field
P1 = (10.0 - 0.475 * math.cos(YAW), 5.0 - 0.475 * math.sin(YAW), 1.10)
P2 = (10.0 + 0.475 * math.cos(YAW), 5.0 + 0.475 * math.sin(YAW), 1.10)
STEP_M = 0.1  # how far the robot goes per epoch


def more_than(n: int) -> Callable[[Sized], bool]:
    return lambda ms: len(ms) > n


@dataclasses.dataclass
class Gnss:
    """A running gnss service on one backend, and the simulator's end of it."""

    backend: str
    service: GnssService
    fixes: dict[int, Record[NavSatFix]]
    headings: Record[GnssHeading]
    truth: Publisher[SimAntennas]
    # bytes onto antenna 1's line, between two epochs
    corrupt: Callable[[bytes], None]
    k: int = 0

    def send(self, **faults: object) -> None:
        """The next epoch of antenna truth: 10 Hz of sim time, the robot driving 1 m/s
        along the field's x (so a fix tells its epoch: :meth:`epoch`)."""
        dx, stamp = STEP_M * self.k, self.k * NS // 10
        p1, p2 = (P1[0] + dx, *P1[1:]), (P2[0] + dx, *P2[1:])
        self.truth.put(SimAntennas(stamp_ns=stamp, p1=p1, p2=p2, **faults))  # type: ignore[arg-type]
        self.k += 1

    def epoch(self, fix: NavSatFix) -> int:
        """The epoch of an RTK-fixed ``fix`` (its noise is millimetres, a step 0.1 m)."""
        x, _, _ = self.service.frame.wgs84_to_field(fix.latitude, fix.longitude, fix.altitude)
        return round((float(x) - (P1 if fix.antenna == 1 else P2)[0]) / STEP_M)

    def step(self, rec: Record[NavSatFix] | Record[GnssHeading], **faults: object) -> None:
        """One epoch, and wait until ``rec`` has something more."""
        grew = more_than(len(rec))
        self.send(**faults)
        assert rec.until(grew, timeout=5.0), f"{self.backend}: nothing came"

    def start(self) -> None:
        """Epochs until a heading comes (a link is up only once its reader has
        connected: epochs before that go to nobody, as on a real wire)."""
        for _ in range(100):
            grew = more_than(len(self.headings))
            self.send()
            if self.headings.until(grew, timeout=0.2):
                return
        pytest.fail(f"{self.backend}: no heading within 100 epochs")


def _wires(
    run: Running, bus: Bus, backend: str, tmp: Path
) -> tuple[list[AntennaConfig], Callable[[bytes], None]]:
    """The simulated Reach M2s on their wires (TCP or a pty) on ``bus``, as
    ``reach-sim`` runs them: the antennas of the gnss config that reads them, and
    antenna 1's line."""
    tcp = backend == "nmea-tcp"
    outputs = [
        ReachOutput(id=a, tcp_port=0) if tcp else ReachOutput(id=a, pty=str(tmp / f"gnss{a}.pty"))
        for a in (1, 2)
    ]
    reach = ReachSim(context(bus, "reach-sim", tmp), ReachSimConfig(outputs=outputs, rtk=HELD))
    run.start(reach, "reach-sim")
    if tcp:
        tcps = reach.servers
        ants = [AntennaConfig(id=a, host=s.host, tcp_port=s.port) for a, s in tcps.items()]
        return ants, tcps[1].send
    ptys = reach.lines
    return [AntennaConfig(id=a, port=str(ln.link)) for a, ln in ptys.items()], ptys[1].send


def _pusher(rx: SimReceiver) -> Callable[[bytes], None]:
    return lambda data: rx._push(data.decode("ascii"))


@pytest.fixture(params=BACKENDS)
def gnss(
    request: pytest.FixtureRequest, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> Iterator[Gnss]:
    backend: str = request.param
    with sessions(router_endpoint, "reach-sim", "gnss") as ((reach_bus, bus), _, run):
        antennas = [AntennaConfig(id=1), AntennaConfig(id=2)]
        corrupt: Callable[[bytes], None] | None = None
        if backend != "sim":
            antennas, corrupt = _wires(run, reach_bus, backend, tmp_path)
        cfg = GnssConfig(backend=backend, antennas=antennas, rtk=HELD)  # type: ignore[arg-type]
        service = GnssService(context(bus, "gnss", tmp_path), cfg)
        if corrupt is None:  # the sim backend's line: where its receiver's text goes
            corrupt = _pusher(cast(SimReceiver, service.receivers[0]))
        rig = Gnss(
            backend,
            service,
            {a: record(client_bus, keys.GNSS_FIX.at(antenna=a)) for a in (1, 2)},
            record(client_bus, keys.GNSS_HEADING),
            client_bus.publisher(keys.SIM_ANTENNAS),
            corrupt,
        )
        run.start(service, "gnss")
        assert rig.truth.wait_matched(timeout=10)
        rig.start()
        yield rig


def test_fixes_carry_the_fix_quality_and_the_receivers_precision(gnss: Gnss) -> None:
    fixes = gnss.fixes[1]
    for _ in range(5):
        gnss.step(fixes)
    fix = fixes[-1]
    assert fix.antenna == 1 and fix.fix_type == FixType.FIX
    sd = np.sqrt(np.diag(np.reshape(fix.position_covariance, (3, 3))))
    assert np.all(sd > 0) and np.all(sd[:2] < 0.02), sd  # RTK fixed: millimetres
    assert fix.num_satellites > 0 and fix.hdop > 0
    # a forced float: quality 5 and decimetres of sigma, then fixed again
    for _ in range(3):
        gnss.step(fixes, force_float1=True)
    fl = fixes.wait_for(lambda f: f.fix_type == FixType.FLOAT, timeout=1.0)
    assert fl is not None, [f.fix_type for f in fixes]
    assert 0.05 < math.sqrt(fl.position_covariance[0]) < 1.0, fl.position_covariance
    n = len(fixes)
    gnss.step(fixes)
    assert fixes.until(lambda fs: fs[-1].fix_type == FixType.FIX and len(fs) > n, timeout=5.0)


def test_a_receiver_in_an_outage_sends_no_fix_and_the_other_goes_on(gnss: Gnss) -> None:
    outage = range(gnss.k, gnss.k + 3)
    for _ in outage:
        gnss.send(outage1=True)
    after = gnss.k
    gnss.send()
    for a in (1, 2):  # each antenna's fixes come in order: the outage's first
        assert gnss.fixes[a].wait_for(lambda f: gnss.epoch(f) == after, timeout=5.0), a
    assert not {gnss.epoch(f) for f in gnss.fixes[1]} & set(outage)
    assert set(outage) <= {gnss.epoch(f) for f in gnss.fixes[2]}


def test_the_heading_of_the_two_antennas_is_near_the_truth(gnss: Gnss) -> None:
    for _ in range(250):
        gnss.step(gnss.headings)
    valid = [h for h in gnss.headings if h.valid]
    assert len(valid) > 200, (len(gnss.headings), len(valid))
    err = np.degrees([(h.yaw - YAW + math.pi) % (2 * math.pi) - math.pi for h in valid])
    # Reach M2 fix noise 7 mm per axis on a 0.95 m baseline: ~0.6 deg SD (time-correlated)
    assert abs(err.mean()) < 1.0 and 0.2 < err.std() < 1.5, (err.mean(), err.std())
    assert all(abs(h.baseline_m - 0.95) < 0.06 for h in valid)
    assert all(0 < h.yaw_sd < math.radians(5.0) for h in valid)


def test_bad_sentences_are_dropped_counted_and_logged_once(
    gnss: Gnss, caplog: pytest.LogCaptureFixture
) -> None:
    good = format_gga(
        Gga(time_s=3600.0, lat_deg=33.717, lon_deg=-83.308, alt_msl_m=200.0, geoid_sep_m=0.0,
            quality=FixType.FIX, num_sats=20, hdop=0.6)
    )  # fmt: skip
    bad = [good.replace("*", "*0"), "$GPGGA,123\r\n", "\x00 garbage\r\n", good[:30] + "\r\n"]
    fixes = gnss.fixes[1]
    with caplog.at_level("WARNING", logger="gnss"):
        for _ in range(3):
            gnss.corrupt("".join(bad).encode("ascii"))
            gnss.step(fixes)
    for _ in range(5):  # and fixes go on from the receiver's own sentences
        gnss.step(fixes)
    bus = gnss.service.ctx.bus
    assert bus.decode_stats.by_key.get("gnss/1/nmea", 0) >= 9, bus.decode_stats.by_key
    assert bus.reports()["antenna1_garbage_bytes"] > 0
    warned = [r for r in caplog.records if "dropped sentence" in r.getMessage()]
    assert len(warned) == 1, caplog.text
