"""Lane reservations between robots sharing a field: the rule each one applies. Pure.

Each robot's mission keeps the lane segments (:mod:`common.lanes`) it *holds* (it
may be in them) and those it *wants* (the next route's), and answers the others'
questions with both. To take segments a robot first makes them wanted, so that
anyone asking sees them, then asks every other robot (:func:`decide`):

- a robot that does not answer (restarting, or cut off by a partition) may hold
  anything: back off (forget what was wanted, wait, ask again);
- a segment another robot holds: back off until it is released. A robot that kept
  wanting while it waited would keep the holder from taking the segments it needs
  to drive away, and each would wait for the other for good;
- a segment another robot wants as well: neither takes it this time; the robot
  whose name sorts later backs off, the other keeps wanting it, asks again sooner,
  and finds it free;
- none of these: the segments are held.

No two robots ever hold one segment. Suppose A and B both came to hold s. A wanted s
from some time a on, without a break, until it held it, and got it because an
answer B gave at some time t_A, after a, said B neither held nor wanted s; likewise
B from b on, and A's answer at t_B after b. B wanted or held s from b on, so t_A <
b; in the same way t_B < a. Then a < t_A < b < t_B < a: a contradiction. It needs
only that an answer tells what its robot held and wanted when it answered, which a
mission's Zenoh queryable does. (A robot named first that took a segment another
wants, rather than waiting for it to back off, would break it: the other may have
had its answers already. ``tests/mission/test_reservation.py`` finds that race.)

Open-RMF's traffic schedule does this with itineraries in time negotiated through a
central database; a field's lanes are few and narrow, so one robot a segment, agreed
between the robots themselves with nobody in the middle, is enough, and it keeps
working with the base station out of reach.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

from common.messages.mission import LaneClaims


@dataclasses.dataclass(frozen=True)
class Verdict:
    """``granted``; else ``back_off`` (forget the wanted segments before asking again)
    or wait, ``why`` naming whom for."""

    granted: bool
    back_off: bool = False
    why: str = ""


GRANTED = Verdict(True)


def decide(me: str, wanted: set[str], answers: Mapping[str, LaneClaims | None]) -> Verdict:
    """What ``me``, wanting ``wanted``, may do given each other robot's answer (None:
    it did not answer)."""
    silent = sorted(r for r, a in answers.items() if a is None)
    if silent:
        return Verdict(False, back_off=True, why=f"no answer from {', '.join(silent)}")
    for robot, a in sorted(answers.items()):
        assert a is not None
        held = wanted & set(a.held)
        if held:
            return Verdict(False, back_off=True, why=f"{robot} holds {', '.join(sorted(held))}")
    for robot, a in sorted(answers.items()):
        assert a is not None
        both = wanted & set(a.wanted)
        if both:  # the one named later steps back; neither takes them this time
            return Verdict(
                False, back_off=robot < me, why=f"{robot} wants {', '.join(sorted(both))}"
            )
    return GRANTED


def deadlocked(
    me: str, held: set[str], wanted: set[str], answers: Mapping[str, LaneClaims | None]
) -> str:
    """The peer ``me`` and it wait for each other: it holds some of what ``me`` wants
    and waits for some of what ``me`` holds, and is named first, so ``me`` is the
    one to give way (its mission surveys another location first); "" when none."""
    for robot, a in sorted(answers.items()):
        if a is not None and robot < me and wanted & set(a.held) and held & set(a.waiting):
            return robot
    return ""


@dataclasses.dataclass
class Claims:
    """One robot's reservations: what it holds and wants, and waits for."""

    held: set[str] = dataclasses.field(default_factory=set)
    wanted: set[str] = dataclasses.field(default_factory=set)
    waiting: set[str] = dataclasses.field(default_factory=set)

    def answer(self, robot: str) -> LaneClaims:
        return LaneClaims(
            robot=robot,
            held=sorted(self.held),
            wanted=sorted(self.wanted),
            waiting=sorted(self.waiting),
        )

    def grant(self) -> None:
        self.held |= self.wanted
        self.wanted = set()
        self.waiting = set()

    def keep(self, segments: set[str]) -> None:
        """Release every held segment but ``segments``; forget what was wanted."""
        self.held &= segments
        self.wanted = set()
        self.waiting = set()
