"""The campaign's partition case: the robot and the base station on two network
namespaces joined by a veth pair, the link cut for 30 s during a survey.

The robot (every service under ``phenorover up``) runs in a namespace of its own; the
base station is the campaign's own process, a Zenoh client in the root namespace
reaching the robot's router across the veth, as the laptop's CLI and dashboard do. The
cut takes the root end of the link down: packets vanish, no connection is refused, so
each side learns of it only when its Zenoh lease expires, as on a real radio link.
Needs root (``ip netns``).
"""

from __future__ import annotations

import contextlib
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

from common import keys
from common.messages.mission import MissionPhase
from services.mission.log import MissionLog
from tests.bench.fault_cases import FIELD_HZ, Case, Truth, finish, survey_verdict
from tests.conftest import Procs, record
from tests.integration.test_mission import Deployment

NS = "phenorover-robot"
ROOT_IF, NS_IF = "prbase0", "prrobot0"
# a /30 of the namespaces this case creates; nothing outside this host is addressed
ROOT_IP, NS_IP = "10.231.77.1", "10.231.77.2"
CUT_S = 30.0
HEAL_S = 2.0


def ip(*args: str, check: bool = True) -> None:
    r = subprocess.run(["ip", *args], capture_output=True, text=True)
    if check and r.returncode:
        raise RuntimeError(f"ip {' '.join(args)}: {r.stderr.strip()}")


@contextlib.contextmanager
def robot_namespace() -> Iterator[None]:
    ip("netns", "del", NS, check=False)  # left over from an interrupted run
    ip("link", "del", ROOT_IF, check=False)
    ip("netns", "add", NS)
    try:
        ip("link", "add", ROOT_IF, "type", "veth", "peer", "name", NS_IF)
        ip("link", "set", NS_IF, "netns", NS)
        ip("addr", "add", f"{ROOT_IP}/30", "dev", ROOT_IF)
        ip("link", "set", ROOT_IF, "up")
        ip("-n", NS, "addr", "add", f"{NS_IP}/30", "dev", NS_IF)
        ip("-n", NS, "link", "set", NS_IF, "up")
        ip("-n", NS, "link", "set", "lo", "up")
        yield
    finally:
        ip("link", "del", ROOT_IF, check=False)
        ip("netns", "del", NS, check=False)


def partition(procs: Procs, tmp: Path) -> tuple[bool, str, dict[str, float]]:
    with robot_namespace():
        d = Deployment(
            procs, tmp, host=NS_IP, wrap=("ip", "netns", "exec", NS), hz=FIELD_HZ, home=True
        )
        try:
            truth = Truth(d)
            seen = record(d.bus, keys.MISSION_EVENT)  # the base station's view
            s = d.start()
            d.wait(lambda x: x.phase == MissionPhase.SCANNING and x.current_scan == 1)
            log = MissionLog(d.runs / s.mission / "mission.db")
            before = len(log.events())
            ip("link", "set", ROOT_IF, "down")
            # the cut lasts CUT_S whatever happens; the robot's own log is read through
            # the shared file system, not the cut link
            time.sleep(CUT_S)
            logged = log.events()
            gap = logged[before:]
            ip("link", "set", ROOT_IF, "up")
            t0 = time.monotonic()
            want = {(t, text) for t, _, text in logged}
            healed = seen.until(lambda ms: want <= {(m.stamp_ns, m.text) for m in ms}, 30.0)
            heal_s = time.monotonic() - t0
            log.close()
            final = finish(d, s.mission)
            ok, text, figs = survey_verdict(d, s.mission, truth)
            got = {(m.stamp_ns, m.text) for m in seen}
            missing = len(want - got)
            twice = len(seen) - len({(m.stamp_ns, m.text) for m in seen})
            figs |= {"gap_events": len(gap), "heal_s": heal_s, "missing": missing, "twice": twice}
            text += (
                f"; {len(gap)} events during the cut, "
                + (
                    f"all at the base station {heal_s:.1f} s after the link's return"
                    if healed
                    else f"{missing} never reached the base station"
                )
                + (f", {twice} twice" if twice else "")
            )
            done = final.phase == MissionPhase.DONE
            passed = ok and done and healed and heal_s <= HEAL_S and bool(gap) and not twice
            return passed, text, figs
        finally:
            d.close()


CASE = Case(
    "partition-30s",
    f"robot / base station link cut for {CUT_S:.0f} s during a survey (two network namespaces)",
    "the robot carries on; every event of the gap reaches the base station within 2 s "
    "of the link's return, once",
    partition,
)
