"""A fault scheduled in the simulator's config reaches the devices: real processes
(sim, gnss, base, nav) on a loopback router, an RTK outage in sim time, and the
fixes and the localization it takes away and gives back."""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path
from typing import Generic, TypeVar

from common import keys
from common.client import wait_alive
from common.clock import NS
from common.keys import Topic
from common.messages.core import Message
from common.transport import Bus
from tests.conftest import REPO, Procs

TINY = str(REPO / "tests" / "data" / "tiny.toml")
RTF = 4.0
AT_S, FOR_S = 12.0, 10.0  # sim seconds: 3 and 2.5 s of wall time at 4x
M = TypeVar("M", bound=Message)


class Stream(Generic[M]):
    """Every message on a topic; waits for one that satisfies a predicate."""

    def __init__(self, bus: Bus, topic: Topic[M]) -> None:
        self.seen: list[M] = []
        self._cond = threading.Condition()
        bus.subscribe(topic, self._add)

    def _add(self, m: M) -> None:
        with self._cond:
            self.seen.append(m)
            self._cond.notify_all()

    def wait_for(self, pred: Callable[[M], bool], timeout: float) -> M | None:
        with self._cond:
            self._cond.wait_for(lambda: any(pred(m) for m in self.seen), timeout)
            return next((m for m in self.seen if pred(m)), None)

    def between(self, t0_s: float, t1_s: float) -> list[M]:
        """Those stamped within [t0_s, t1_s] sim seconds."""
        with self._cond:
            return [m for m in self.seen if t0_s * NS <= m.stamp_ns <= t1_s * NS]


def test_rtk_outage_stops_the_fixes_and_localization_for_its_window(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    common = ("--clock", "sim", "--field", TINY)
    fixes = {a: Stream(client_bus, keys.GNSS_FIX.at(antenna=a)) for a in (1, 2)}
    poses = Stream(client_bus, keys.NAV_POSE)
    # the devices and nav first: they wait on the sim clock, so the world (and the
    # fault's sim time) starts only when all of them listen
    for name, sets in (
        ("base", ["backend=sim"]),
        ("gnss", ["backend=sim"]),
        # fixes late by 50 ms of wall time are 0.2 s late in sim time at 4x
        ("nav", [f"max_fix_age_s={0.15 * RTF}"]),
    ):
        args = [a for s in sets for a in ("--set", s)]
        procs.service(f"services.{name}", router_endpoint, *common, *args, log=tmp_path / name)
    assert wait_alive(client_bus.session, {"base", "gnss", "nav"}, timeout=30)
    fault = f"faults=[{{kind='rtk_outage', at_s={AT_S}, for_s={FOR_S}}}]"
    # a world of its own from sim time 0: no snapshot read from or left in runs/
    sim_sets = [f"real_time_factor={RTF}", "resume=false", "snapshot_s=0", fault]
    args = [a for s in sim_sets for a in ("--set", s)]
    procs.service("services.sim", router_endpoint, *common, *args, log=tmp_path / "sim")

    before = poses.wait_for(lambda p: p.localized and p.stamp_ns < AT_S * NS, timeout=30)
    assert before is not None, "never localized before the outage"
    end = (AT_S + FOR_S) * NS
    # the gnss service stamps on its copy of the sim clock, a step or two behind
    back = {a: s.wait_for(lambda f: f.stamp_ns > end + NS, timeout=30) for a, s in fixes.items()}
    assert all(back.values()), "the fixes did not come back after the outage"
    assert poses.wait_for(lambda p: p.localized and p.stamp_ns > end, timeout=10), (
        "not localized again after the outage"
    )
    for a, s in fixes.items():
        assert s.between(0.0, AT_S - 1.0), f"antenna {a}: no fixes before the outage"
        gap = s.between(AT_S + 0.5, AT_S + FOR_S - 0.5)
        assert not gap, f"antenna {a}: {len(gap)} fixes during the outage"
    # the outage's inside: a second for localization to lapse, and at its end the
    # same half second of clock skew as the fixes' gap above (the first fix back can
    # be stamped a step before the end on the gnss service's copy of the clock)
    during = poses.between(AT_S + 1.0, AT_S + FOR_S - 0.5)
    wrong = [p.stamp_ns / NS for p in during if p.localized]
    assert during and not wrong, f"localized without fixes at sim {wrong} s"
    log = (tmp_path / "sim").read_text()
    assert f"fault rtk_outage: start ({FOR_S:g} s) both antennas" in log
    assert "fault rtk_outage: end" in log
