"""The lane reservation rule: no two robots ever hold one segment, whatever the order
in which their steps and questions interleave; a silent peer makes a robot wait."""

from __future__ import annotations

import dataclasses

from hypothesis import given, settings
from hypothesis import strategies as st

from common.messages.mission import LaneClaims
from services.mission.reservation import Claims, deadlocked, decide

ROBOTS = ("r1", "r2", "r3")
SEGMENTS = ("a", "b", "c")


def test_held_by_a_peer_or_wanted_by_a_first_named_peer_backs_off() -> None:
    free = LaneClaims(robot="r2")
    assert decide("r1", {"a"}, {"r2": free}).granted
    # held by a peer: forget the wish while waiting, or the holder could not leave
    v = decide("r1", {"a", "b"}, {"r2": LaneClaims(robot="r2", held=["b"])})
    assert not v.granted and v.back_off and v.why == "r2 holds b"
    # both want a: neither takes it; the robot named later backs off, the other waits
    v = decide("r1", {"a"}, {"r2": LaneClaims(robot="r2", wanted=["a"])})
    assert not v.granted and not v.back_off and v.why == "r2 wants a"
    v = decide("r2", {"a"}, {"r1": LaneClaims(robot="r1", wanted=["a"])})
    assert not v.granted and v.back_off
    # a peer that does not answer (restarting, or beyond a partition) may hold anything
    v = decide("r1", {"a"}, {"r2": None, "r3": free})
    assert not v.granted and v.back_off and v.why == "no answer from r2"


@dataclasses.dataclass
class Robot:
    """One robot of the interleaving model: its claims and where it is in a round of
    wanting, asking each peer (one step a peer) and deciding."""

    name: str
    claims: Claims = dataclasses.field(default_factory=Claims)
    target: set[str] = dataclasses.field(default_factory=set)
    asked: dict[str, LaneClaims] = dataclasses.field(default_factory=dict)
    resting: int = 0  # steps left of a back-off (twice a round of asking, as retry_s)

    def step(self, robots: dict[str, Robot], target: set[str]) -> None:
        peers = [p for p in robots if p != self.name]
        if self.resting:
            self.resting -= 1
            return
        if not self.claims.wanted:
            if self.claims.held and target <= self.claims.held:
                self.claims.keep(set())  # done with them: released
                return
            self.target = target
            self.claims.wanted = target - self.claims.held
            self.asked = {}
            return
        missing = [p for p in peers if p not in self.asked]
        if missing:  # an answer tells what the peer holds and wants right now
            self.asked[missing[0]] = robots[missing[0]].claims.answer(missing[0])
            return
        v = decide(self.name, self.target, self.asked)
        if v.granted:
            self.claims.grant()
        elif v.back_off:
            self.claims.wanted = set()
            self.resting = 2 * (len(peers) + 1)
        else:
            self.asked = {}  # ask again


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.sampled_from(ROBOTS),
            st.sets(st.sampled_from(SEGMENTS), min_size=1, max_size=2),
        ),
        min_size=1,
        max_size=300,
    )
)
def test_no_two_robots_ever_hold_one_segment(schedule: list[tuple[str, set[str]]]) -> None:
    robots = {n: Robot(n) for n in ROBOTS}
    for name, target in schedule:
        robots[name].step(robots, target)
        held = [r.claims.held for r in robots.values()]
        for i, a in enumerate(held):
            for b in held[i + 1 :]:
                assert not a & b, [(r.name, r.claims) for r in robots.values()]


def test_the_model_can_fail_without_wanting_first() -> None:
    """The race the rule exists for is real: two robots that ask before their wanting
    is visible are both granted the segment by the rule itself (the interleavings
    above never ask before wanting, which is what keeps them apart)."""
    a, b = Robot("r1"), Robot("r2")
    # both ask while neither wants anything yet, then both decide
    seen_by_a, seen_by_b = b.claims.answer("r2"), a.claims.answer("r1")
    a.claims.wanted, b.claims.wanted = {"s"}, {"s"}
    assert decide("r1", {"s"}, {"r2": seen_by_a}).granted
    assert decide("r2", {"s"}, {"r1": seen_by_b}).granted


def test_robots_taking_turns_each_get_the_segment_they_all_want() -> None:
    """Three robots want one segment at once and take turns; each, once through it,
    drives on to segments of its own: every one of them gets through."""
    robots = {n: Robot(n) for n in ROBOTS}
    through: set[str] = set()
    for k in range(300):
        name = ROBOTS[k % len(ROBOTS)]
        robots[name].step(robots, {name} if name in through else {"a"})
        through |= {n for n, r in robots.items() if "a" in r.claims.held}
    assert through == set(ROBOTS)


def test_a_robot_waiting_for_a_held_segment_lets_the_holder_drive_away() -> None:
    """r1 stands in a (holds it) and must drive on through b; r2's route needs a and b:
    r2 backs off while a is held, so r1 gets b and can leave (a first version, whose
    waiting robots kept wanting, deadlocked here in the two-robot simulation: r2
    waited for r1's a, r1 for r2 to stop wanting b)."""
    robots = {n: Robot(n) for n in ("r1", "r2")}
    robots["r1"].claims.held = {"a"}
    for k in range(100):
        name = ("r1", "r2")[k % 2]
        robots[name].step(robots, {"a", "b"})
        if "b" in robots["r1"].claims.held:
            break
    assert "b" in robots["r1"].claims.held, [(r.name, r.claims) for r in robots.values()]


def test_two_robots_each_standing_in_the_others_way_the_later_named_gives_way() -> None:
    # r1 stands in a and waits for b; r2 stands in b and wants a
    r1 = LaneClaims(robot="r1", held=["a"], waiting=["b"])
    r2 = LaneClaims(robot="r2", held=["b"], waiting=["a"])
    assert deadlocked("r2", {"b"}, {"a", "b"}, {"r1": r1}) == "r1"
    assert deadlocked("r1", {"a"}, {"a", "b"}, {"r2": r2}) == ""  # named first: it waits
    # r1 waits for something else: no deadlock, r2 just waits
    other = LaneClaims(robot="r1", held=["a"], waiting=["c"])
    assert deadlocked("r2", {"b"}, {"a", "b"}, {"r1": other}) == ""
    assert deadlocked("r2", {"b"}, {"a", "b"}, {"r1": None}) == ""
