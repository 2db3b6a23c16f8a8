"""The simulator's fault schedule: decoding and validation from the manifest's
``[[services.sim.faults]]``, activation windows in sim time, the combined effect on
the devices, start/end reporting, the lidar seeing a transient obstacle, and the
simulator (run flat out, publishing into a fake bus) applying every kind to its
device data while the truth stays the same as without faults."""

from __future__ import annotations

import logging
import threading
import tomllib
from pathlib import Path
from typing import Any, cast

import numpy as np
import pytest

from common import keys
from common.clock import NS, WallClock
from common.config import ConfigError, decode_section
from common.field import load_field
from common.messages.sim import SimClock as SimClockMsg
from common.service import Context
from common.transport import Bus
from services.sim.config import SimConfig
from services.sim.faults import (
    NONE,
    Fault,
    FaultSchedule,
    Multipath,
    OdometryFreeze,
    RtkFloat,
    RtkOutage,
    TransientObstacle,
    describe,
    effects,
)
from services.sim.robot import RobotState
from services.sim.service import SimService
from services.sim.world import World
from tests.conftest import REPO

TINY = str(REPO / "tests" / "data" / "tiny.toml")

TOML = """
[[faults]]
kind = "rtk_outage"
at_s = 5
for_s = 20
[[faults]]
kind = "rtk_float"
at_s = 30.0
for_s = 10.0
antenna = 2
[[faults]]
kind = "multipath"
at_s = 40.0
for_s = 5.0
antenna = 1
offset_m = [0.5, -0.25]
[[faults]]
kind = "odometry_freeze"
at_s = 50.0
for_s = 5.0
mode = "silent"
[[faults]]
kind = "obstacle"
at_s = 60.0
for_s = 8.0
x = 3.0
y = 0.4
"""


def _decode(text: str) -> SimConfig:
    return decode_section(tomllib.loads(text), SimConfig, "m.toml: [services.sim]")


def test_every_kind_decodes_from_toml() -> None:
    faults = _decode(TOML).faults
    assert faults == [
        RtkOutage(at_s=5.0, for_s=20.0),
        RtkFloat(at_s=30.0, for_s=10.0, antenna=2),
        Multipath(at_s=40.0, for_s=5.0, antenna=1, offset_m=(0.5, -0.25)),
        OdometryFreeze(at_s=50.0, for_s=5.0, mode="silent"),
        TransientObstacle(at_s=60.0, for_s=8.0, x=3.0, y=0.4),
    ]
    assert _decode("").faults == []


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        (
            'kind = "rtk_outgae"\nat_s = 1\nfor_s = 1',
            "Invalid value 'rtk_outgae' - at `$.faults[0].kind`",
        ),
        ("at_s = 1\nfor_s = 1", "missing required field `kind`"),
        ('kind = "rtk_outage"\nat_s = -1\nfor_s = 1', ">= 0.0 - at `$.faults[0].at_s`"),
        ('kind = "rtk_outage"\nat_s = 1\nfor_s = 0', "> 0.0 - at `$.faults[0].for_s`"),
        ('kind = "rtk_outage"\nat_s = 1\nfor_s = 1\nantenna = 3', "antenna"),
        ('kind = "rtk_outage"\nat_s = 1\nfor_s = 1\nantena = 1', "unknown field `antena`"),
        ('kind = "multipath"\nat_s = 1\nfor_s = 1\nantenna = 1', "`offset_m`"),
        ('kind = "obstacle"\nat_s = 1\nfor_s = 1\nx = nan\ny = 0', "`$.faults[0].x`"),
        ('kind = "odometry_freeze"\nat_s = 1\nfor_s = 1\nmode = "stale"', "mode"),
    ],
)
def test_a_bad_entry_is_one_clear_line(entry: str, message: str) -> None:
    with pytest.raises(ConfigError) as err:
        _decode(f"[[faults]]\n{entry}\n")
    text = str(err.value)
    assert "\n" not in text and text.startswith("m.toml: [services.sim]: ")
    assert message in text


def test_window_is_half_open_in_sim_seconds() -> None:
    f = RtkOutage(at_s=5.0, for_s=2.0)
    assert [f.active(t) for t in (4.999, 5.0, 6.999, 7.0)] == [False, True, True, False]
    sched = FaultSchedule([f, RtkFloat(at_s=6.0, for_s=10.0, antenna=1)])
    assert sched.active(0.0) == () and sched.effects(0.0) is NONE
    assert len(sched.active(6.5)) == 2 and sched.active(8.0) == (sched.faults[1],)
    assert FaultSchedule([]).effects(6.0) is NONE


def test_effects_combine_per_antenna() -> None:
    fx = effects(
        [
            RtkOutage(at_s=0, for_s=1, antenna=2),
            RtkFloat(at_s=0, for_s=1),
            Multipath(at_s=0, for_s=1, antenna=1, offset_m=(1.0, 2.0)),
            Multipath(at_s=0, for_s=1, antenna=1, offset_m=(0.5, 0.0)),
            OdometryFreeze(at_s=0, for_s=1),
            TransientObstacle(at_s=0, for_s=1, x=1.0, y=2.0, height=1.5),
        ]
    )
    assert fx.outage == (False, True) and fx.force_float == (True, True)
    assert fx.offset == ((1.5, 2.0), (0.0, 0.0))
    assert fx.encoders == "zero"
    assert [(b.x, b.y, b.height) for b in fx.obstacles] == [(1.0, 2.0, 1.5)]
    both = effects(
        [OdometryFreeze(at_s=0, for_s=1), OdometryFreeze(at_s=0, for_s=1, mode="silent")]
    )
    assert both.encoders == "silent"
    assert effects([RtkOutage(at_s=0, for_s=1)]).outage == (True, True)


def test_each_start_and_end_is_reported_once() -> None:
    a = RtkOutage(at_s=1.0, for_s=2.0)
    b = Multipath(at_s=2.0, for_s=5.0, antenna=2, offset_m=(0.3, 0.0))
    blink = RtkFloat(at_s=3.1, for_s=0.01)  # falls between two steps: never acted
    sched = FaultSchedule([a, b, blink])
    seen = {t: sched.changes(t) for t in (0.0, 1.0, 1.5, 2.0, 3.0, 3.5, 7.0, 8.0)}
    assert seen == {
        0.0: [],
        1.0: [(a, True)],
        1.5: [],
        2.0: [(b, True)],
        3.0: [(a, False)],
        3.5: [],
        7.0: [(b, False)],
        8.0: [],
    }
    assert describe(a, True) == "fault rtk_outage: start (2 s) both antennas"
    assert describe(a, False) == "fault rtk_outage: end"
    assert describe(b, True) == "fault multipath: start (5 s) antenna 2, offset (0.3, 0) m"


def test_lidar_sees_a_transient_obstacle_and_the_same_noise() -> None:
    w = World(*load_field("spl"))
    state = w.settle(RobotState(x=1.0, y=0.4, yaw=0.0))
    clear = w.lidar_scan(state, np.random.default_rng(0))
    box = TransientObstacle(at_s=0, for_s=1, x=3.0, y=0.4, size_x=0.2, size_y=0.6).box()
    seen = w.lidar_scan(state, np.random.default_rng(0), [box])
    lx = w.robot.lidar.x
    assert abs(seen[540] - (3.0 - 0.1 - 1.0 - lx)) < 0.1
    assert not abs(clear[540] - seen[540]) < 0.5
    # beams that miss the box read exactly what they read without it
    miss = np.abs(np.arange(len(seen)) - 540) > 120
    np.testing.assert_array_equal(clear[miss], seen[miss])
    # the world itself is unchanged: gone with the fault
    np.testing.assert_array_equal(w.lidar_scan(state, np.random.default_rng(0)), clear)


class _Recorder:
    def __init__(self, out: list[tuple[str, Any]], key: str) -> None:
        self._out, self._key = out, key

    def put(self, msg: Any) -> None:
        self._out.append((self._key, msg))


class _FakeBus:
    """Records what the simulator publishes; nothing comes in."""

    def __init__(self) -> None:
        self.out: list[tuple[str, Any]] = []

    def publisher(self, topic: Any) -> _Recorder:
        return _Recorder(self.out, topic.key)

    def subscribe(self, topic: Any, callback: Any) -> None:
        pass

    def serve(self, rpc: Any, handler: Any) -> None:
        pass


def _simulate(tmp: Path, faults: list[Fault], until_s: float) -> dict[str, list[Any]]:
    """Run the simulator flat out until sim time ``until_s``; what it published, by key."""
    bus = _FakeBus()
    ctx = Context("sim", "test", cast(Bus, bus), WallClock(), logging.getLogger("sim"), tmp, TINY)
    cfg = SimConfig(real_time_factor=1000.0, resume=False, snapshot_s=0.0, faults=faults)
    svc = SimService(ctx, cfg)
    stop = threading.Event()

    class _StopAt(_Recorder):
        def put(self, msg: SimClockMsg) -> None:
            super().put(msg)
            if msg.sim_ns >= until_s * NS:
                stop.set()

    svc.clock_pub = _StopAt(bus.out, "clock")  # type: ignore[assignment]
    svc.run(stop)
    out: dict[str, list[Any]] = {}
    for key, msg in bus.out:
        out.setdefault(key, []).append(msg)
    return out


def test_the_simulator_applies_faults_to_devices_only(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    _, field = load_field(TINY)
    x0, y0 = float(field.origin_xy[0]), float(field.origin_xy[1])
    faults: list[Fault] = [
        OdometryFreeze(at_s=1.0, for_s=1.0),
        Multipath(at_s=2.0, for_s=1.0, antenna=2, offset_m=(0.5, 0.0)),
        OdometryFreeze(at_s=3.0, for_s=1.0, mode="silent"),
        RtkFloat(at_s=4.0, for_s=1.0, antenna=1),
        RtkOutage(at_s=5.0, for_s=1.0, antenna=2),
        TransientObstacle(at_s=6.0, for_s=1.0, x=x0 + 2.0, y=y0),
    ]
    caplog.set_level(logging.INFO, logger="sim")
    faulty = _simulate(tmp_path / "a", faults, 8.0)
    clean = _simulate(tmp_path / "b", [], 8.0)
    truth = keys.SIM_TRUTH.key
    n = min(len(faulty[truth]), len(clean[truth]))
    assert n >= 70 and faulty[truth][:n] == clean[truth][:n]  # the truth stays the truth

    def within(key: str, t0: float, t1: float, run: dict[str, list[Any]]) -> list[Any]:
        return [m for m in run[key] if t0 * NS <= m.stamp_ns < t1 * NS]

    enc = keys.SIM_ENCODERS.key
    assert all((m.v, m.w) == (0.0, 0.0) for m in within(enc, 1.0, 2.0, faulty))
    assert len(within(enc, 1.0, 2.0, faulty)) == 50
    assert within(enc, 3.0, 4.0, faulty) == [] and len(within(enc, 3.0, 4.0, clean)) == 50
    assert within(enc, 4.0, 8.0, faulty) == within(enc, 4.0, 8.0, clean)
    ant = keys.SIM_ANTENNAS.key
    flags = {
        round(m.stamp_ns / NS, 1): (m.offset2, m.force_float1, m.outage2, m.outage1)
        for m in faulty[ant]
    }
    assert flags[1.9] == ((0.0, 0.0), False, False, False)
    assert flags[2.0] == flags[2.9] == ((0.5, 0.0), False, False, False)
    assert flags[4.5] == ((0.0, 0.0), True, False, False)
    assert flags[5.5] == ((0.0, 0.0), False, True, False)
    assert [(m.p1, m.p2) for m in faulty[ant]][:70] == [(m.p1, m.p2) for m in clean[ant]][:70]
    lidar = keys.SIM_LIDAR.key
    mid = {round(m.stamp_ns / NS, 1): float(m.ranges.numpy()[540]) for m in faulty[lidar]}
    expected = 2.0 - 0.2 - 0.45  # box face less the lidar's mount ahead of base_link
    assert abs(mid[6.0] - expected) < 0.1 and abs(mid[6.9] - expected) < 0.1
    assert not abs(mid[5.9] - expected) < 0.3 and not abs(mid[7.0] - expected) < 0.3
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("fault ")]
    assert len(lines) == 12 and lines[0] == "fault odometry_freeze: start (1 s) encoders zero"
    assert "fault obstacle: end" in lines
