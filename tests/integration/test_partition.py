"""A cut link between the robot and the base station: the mission's events of the
gap reach the base station once the link is back (history topics, common.keys).

The two machines are two Zenoh routers on loopback joined through a TCP relay in the
test process, which the test cuts (closing every connection and refusing new ones,
as a link whose far end is unreachable does) and restores.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterator

import pytest
import zenoh

from common import keys
from common.config import zenoh_config
from common.messages.mission import MissionEvent
from common.transport import Bus
from phenorover.eval.relay import Relay
from tests.conftest import free_port, record


@pytest.fixture
def link() -> Iterator[tuple[Bus, Bus, Relay]]:
    robot_ep = f"tcp/127.0.0.1:{free_port()}"
    robot = zenoh.open(zenoh_config("router", [robot_ep], []))
    relay = Relay(int(robot_ep.rsplit(":", 1)[1]))
    base_ep = f"tcp/127.0.0.1:{free_port()}"
    base = zenoh.open(zenoh_config("router", [base_ep], [f"tcp/127.0.0.1:{relay.port}"]))
    # clients: each talks only through its own machine's router, so the relay is the
    # one path between them (peers on one host would find each other directly)
    mission = Bus(zenoh.open(zenoh_config("client", [], [robot_ep])), "mission")
    viz = Bus(zenoh.open(zenoh_config("client", [], [base_ep])), "viz")
    yield mission, viz, relay
    for bus in (viz, mission):
        bus.close()
        bus.session.close()
    relay.close()
    base.close()
    robot.close()


def test_events_of_a_partition_reach_the_base_station_when_it_heals(
    link: tuple[Bus, Bus, Relay],
) -> None:
    mission, viz, relay = link
    # the same stream without history, as a control: its gap is lost
    plain_topic = dataclasses.replace(
        keys.MISSION_EVENT, key=f"{keys.PREFIX}/test/plain", history=0
    )
    plain_events = record(viz, plain_topic)
    plain = mission.publisher(plain_topic)
    pub = mission.publisher(keys.MISSION_EVENT)
    pub.put(MissionEvent(mission="m", level="info", text="before 0"))
    events = record(viz, keys.MISSION_EVENT)  # a late subscriber gets the history

    def texts() -> list[str]:
        return [m.text for m in list(events)]

    def wait_for(want: list[str], timeout: float) -> bool:
        return events.until(lambda ms: set(want) <= {m.text for m in ms}, timeout)

    assert wait_for(["before 0"], timeout=10), texts()
    pub.put(MissionEvent(mission="m", level="info", text="before 1"))
    assert wait_for(["before 1"], timeout=5), texts()

    relay.cut()
    gap = [f"gap {k}" for k in range(20)]
    for text in gap:
        pub.put(MissionEvent(mission="m", level="warning", text=text))
        plain.put(MissionEvent(mission="m", level="warning", text=text))
    assert not wait_for(["gap 0"], timeout=2.0), "an event crossed a cut link"
    relay.restore()
    t0 = time.monotonic()
    assert wait_for(gap, timeout=10), f"missing after the link came back: {texts()}"
    healed = time.monotonic() - t0
    assert healed <= 2.0, f"the gap's events arrived {healed:.1f} s after the link's return"
    assert len(texts()) == len(set(texts())), f"an event came twice: {texts()}"
    pub.put(MissionEvent(mission="m", level="info", text="after"))
    plain.put(MissionEvent(mission="m", level="info", text="after"))
    assert wait_for(["after"], timeout=5)
    assert plain_events.until(lambda ms: any(m.text == "after" for m in ms), timeout=5)
    assert not any(m.text.startswith("gap") for m in plain_events), "the control kept its gap"
