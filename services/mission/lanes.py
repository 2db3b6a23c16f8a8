"""A mission's lane reservations over Zenoh, with the robots sharing its field.

Before each route the mission reserves every lane segment (:mod:`common.lanes`) the
robot will be in along it (its body's reach plus ``margin_m`` for how far it may
stray), as :mod:`.reservation` rules, asking each peer's mission on
``rpc/fleet/lanes/<peer>``; at the route's end it keeps only the segments where it
stands, and along the way it releases what lies behind at the start of each leg. It
answers the peers' questions on its own key from the moment the service starts,
whatever it is doing.

What it holds and wants is written to ``<run_dir>/lanes-<namespace>.json`` before
anyone can learn it (atomically, and before the robot moves into what it was granted),
so a mission restarted mid-survey (a power cut, a crash) answers as it did before:
the segments its robot stands in stay its own. While it is down its peers get no
answer and wait, as they do across a partition: a robot that cannot confirm its
reservation does not drive.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from pathlib import Path

import msgspec
import numpy as np

from common import keys
from common.config import ConfigError
from common.field import load_field
from common.files import write_atomic
from common.lanes import PARK_M, LaneMap, driven_rows, footprint_radius, plan_lanes
from common.messages.mission import LaneClaims, LaneQuery
from common.messages.nav import Leg
from common.messages.plan import PlanResult
from common.service import Context
from common.transport import RpcError
from services.mission.config import LanesConfig
from services.mission.reservation import Claims, deadlocked, decide

log = logging.getLogger(__name__)


class GiveWay(Exception):
    """This robot and a peer named first wait for each other: it gives way."""


class Lanes:
    """This robot's side (``ctx.bus.namespace`` names it) of the reservations with
    ``cfg.peers``; serves its claims from construction."""

    def __init__(self, ctx: Context, cfg: LanesConfig) -> None:
        self.ctx, self.cfg = ctx, cfg
        self.me = ctx.bus.namespace
        if not self.me:
            raise ConfigError(
                "[services.mission.lanes] peers: a robot sharing a field needs a namespace "
                "(the manifest's namespace) to be told apart by"
            )
        if self.me in cfg.peers:  # it would answer itself that it wants its own way
            raise ConfigError(f"[services.mission.lanes] peers: {self.me!r} is this robot")
        _, self.field = load_field(ctx.field)
        # the lanes an ``aha`` survey drives until a mission's plan says (use())
        n = len(self.field.row_lanes_y)
        self.map = LaneMap(self.field, driven_rows("aha", n))
        fp = ctx.robot.footprint
        self.reach = footprint_radius(fp.length, fp.width) + cfg.margin_m
        if self.reach >= PARK_M:  # at home, it would stand in the edge lane's segments
            raise ConfigError(
                f"[services.mission.lanes] margin_m: {cfg.margin_m:g} m; the robot's reach "
                f"({self.reach:.2f} m) must stay under its parking distance of {PARK_M:g} m"
            )
        self.path = Path(ctx.run_dir) / f"lanes-{self.me}.json"
        self._lock = threading.Lock()
        self.claims = self._load()
        self._at_leg: tuple[int, int] = (0, -1)  # the route (its legs' id) and leg last seen
        ctx.bus.serve(keys.FLEET_LANES.at(robot=self.me), self._answer)

    def _load(self) -> Claims:
        try:
            saved = msgspec.json.decode(self.path.read_bytes(), type=LaneClaims)
        except FileNotFoundError:
            return Claims()
        except (OSError, msgspec.DecodeError) as exc:
            # what this robot held is unknown: holding every segment keeps the others
            # out until its first route's reservation says where it is
            self.ctx.log.warning("%s: unreadable (%s): holding every lane segment", self.path, exc)
            return Claims(held=set(LaneMap(self.field).ids))  # every lane, whatever the plan
        if saved.held or saved.wanted:
            self.ctx.log.info(
                "lane reservations carried on from %s: holding %s",
                self.path,
                ", ".join(saved.held) or "none",
            )
        return Claims(held=set(saved.held), wanted=set(saved.wanted))

    def _save(self) -> None:
        # durable: after a power cut the robot still holds the lanes it stands in
        write_atomic(self.path, msgspec.json.encode(self.claims.answer(self.me)), durable=True)

    def _answer(self, q: LaneQuery) -> LaneClaims:
        with self._lock:
            return self.claims.answer(self.me)

    def _ask(self, peer: str) -> LaneClaims | None:
        try:
            return self.ctx.bus.call(
                keys.FLEET_LANES.at(robot=peer),
                LaneQuery(robot=self.me),
                timeout=self.cfg.answer_timeout_s,
            )
        except RpcError:  # no answer, or one that cannot be read: it may hold anything
            return None

    def use(self, plan: PlanResult) -> None:
        """Reserve the lanes ``plan`` drives (:func:`common.lanes.plan_lanes`)."""
        self.map = plan_lanes(self.field, plan)

    def reserve(
        self,
        legs: list[Leg],
        wait: Callable[[float], object],
        say: Callable[[str], None],
        give_way: bool = False,
    ) -> None:
        """Hold every segment along ``legs`` (and those held already), waiting with
        ``wait(seconds)`` (which raises to give up: an abort) until the peers allow
        it; ``say`` is told once per reason to wait. With ``give_way``, raises GiveWay
        when a peer named first and this robot wait for each other (seen twice in a
        row), having forgotten what it wanted."""
        want = self.map.along(legs, self.reach)
        said, stuck = "", 0
        try:
            while True:
                with self._lock:
                    self.claims.wanted = want - self.claims.held
                    if not self.claims.wanted:
                        break
                    self._save()  # wanted, and visible, before anyone is asked
                answers = {p: self._ask(p) for p in self.cfg.peers}
                verdict = decide(self.me, want, answers)
                if verdict.granted:
                    with self._lock:
                        self.claims.grant()
                        self._save()  # held, on disk, before the robot moves into it
                    break
                if verdict.why != said:
                    say(f"lanes: waiting, {verdict.why}")
                    said = verdict.why
                with self._lock:
                    held = set(self.claims.held)
                    self.claims.waiting = {s for a in answers.values() if a for s in a.held} & want
                    if verdict.back_off:
                        self.claims.wanted = set()
                    self._save()
                peer = deadlocked(self.me, held, want, answers)
                stuck = stuck + 1 if peer else 0
                if give_way and stuck >= 2:
                    raise GiveWay(f"{peer} waits for where this robot stands and holds its way")
                wait(2 * self.cfg.retry_s if verdict.back_off else self.cfg.retry_s)
        except BaseException:  # given up (an abort, or giving way): wanting nothing
            with self._lock:
                self.claims.wanted, self.claims.waiting = set(), set()
                self._save()
            raise
        if said:
            say("lanes: reserved, driving on")

    def passed(self, leg: int, legs: list[Leg], x: float, y: float) -> None:
        """On a route of ``legs``, now on leg ``leg`` at (x, y): release what lies
        behind, so that a peer waiting for it need not wait for the route's end. Each
        leg's start is looked at once."""
        if (id(legs), leg) == self._at_leg:
            return
        self._at_leg = (id(legs), leg)
        keep = self.map.at(np.array([[x, y]]), self.reach)[0] | self.map.along(
            legs[leg:], self.reach
        )
        with self._lock:
            if self.claims.held - keep:
                self.claims.held &= keep
                self._save()

    def release_to(self, x: float, y: float) -> None:
        """Keep only the segments a robot at (x, y) is in."""
        here = self.map.at(np.array([[x, y]]), self.reach)[0]
        with self._lock:
            self.claims.keep(here)
            self._save()

    def held(self) -> set[str]:
        with self._lock:
            return set(self.claims.held)
