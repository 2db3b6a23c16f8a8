"""Robots sharing a field keep apart by namespace: each has its own keys, the site's
(the simulated world's clock, the planner) are shared, and the access control grants
a role its keys in any robot's namespace."""

from __future__ import annotations

import pytest

from common import acl, keys
from common.config import ConfigError, Manifest, decode_section
from common.messages.base import Twist
from common.messages.sim import SimClock
from common.streams import Latest
from tests.conftest import client


def test_a_robots_keys_are_under_its_namespace_and_the_sites_are_not() -> None:
    assert keys.NAV_POSE.within("rover2").key == "phenorover/rover2/nav/pose"
    assert keys.GNSS_FIX.at(antenna=1).within("r1").key == "phenorover/r1/gnss/1/fix"
    assert keys.MISSION_CMD.within("r1").key == "phenorover/r1/rpc/mission/cmd"
    assert keys.SIM_RENDER.within("r1").key == "phenorover/r1/rpc/sim/render"
    for site in (keys.SIM_CLOCK, keys.SIM_RUN, keys.PLANNER_PLAN):
        assert site.within("r1").key == site.key
    assert keys.SIM_ACK.at(service="r1.nav").within("r1").key == "phenorover/sim/ack/r1.nav"
    # no namespace, no change: a robot surveying alone keeps the plain keys
    assert keys.NAV_POSE.within("").key == keys.NAV_POSE.key
    assert keys.participant("nav", "r1") == "r1.nav" and keys.participant("nav", "") == "nav"


def test_the_access_control_grants_a_role_its_keys_in_any_namespace() -> None:
    robot = acl.ROLES["robot"]
    assert "phenorover/nav/pose" in robot.publishes
    assert "phenorover/*/nav/pose" in robot.publishes
    assert "phenorover/*/mission/event" in acl.HISTORY
    base = acl.ROLES["basestation"]
    assert base.calls.count("phenorover/rpc/planner/plan") == 1  # the site's: once


@pytest.mark.parametrize("bad", ["a/b", "r*", "$x", "x" * 33])
def test_a_manifest_namespace_that_cannot_be_a_key_chunk_is_refused(bad: str) -> None:
    with pytest.raises(ConfigError, match="namespace"):
        decode_section({"machine": "m", "namespace": bad}, Manifest, "m.toml")


def test_two_robots_on_one_router_hear_only_their_own(router_endpoint: str) -> None:
    with (
        client(router_endpoint, "r1", namespace="r1") as r1,
        client(router_endpoint, "r2", namespace="r2") as r2,
        client(router_endpoint, "base") as base,
    ):
        heard_r2: Latest[Twist] = r2.latest(keys.BASE_CMD_VEL)
        clock_r2: Latest[SimClock] = r2.latest(keys.SIM_CLOCK)
        seen_by_base: Latest[Twist] = base.latest(keys.BASE_CMD_VEL.within("r1"))
        cmd = r1.publisher(keys.BASE_CMD_VEL)
        clock = r1.publisher(keys.SIM_CLOCK)
        got = None
        for _ in range(100):  # until the subscriptions have reached the router
            cmd.put(Twist(stamp_ns=1, linear_x=0.3))
            clock.put(SimClock(stamp_ns=1, sim_ns=1))
            got = seen_by_base.wait_for(lambda m: m.linear_x == 0.3, timeout=0.1)
            if got is not None and clock_r2.wait_for(lambda m: m.sim_ns == 1, timeout=0.1):
                break
        assert got is not None, "the base station never heard robot r1"
        assert clock_r2.get() is not None, "the site's clock did not reach robot r2"
        # the clock went out after r1's command on the same priority: r2 would have
        # heard the command first had it been its key
        assert heard_r2.get() is None


def test_a_key_placed_in_a_robots_namespace_stays_there_on_a_namespaced_bus() -> None:
    """The base station's dashboard names each robot's topics; a bus of its own in a
    namespace does not put them in a second one."""
    theirs = keys.NAV_POSE.within("rover2")
    assert theirs.key == "phenorover/rover2/nav/pose"
    assert theirs.within("base") == theirs and theirs.within("base").key == theirs.key
    assert keys.NAV_POSE.within("") is keys.NAV_POSE
    assert keys.MISSION_CMD.within("r2").within("r3").key == "phenorover/r2/rpc/mission/cmd"
