"""The simulator's side of lockstep without Zenoh: whom a step waits for and what it
expects delivered, with a bus that only records the barrier's callbacks."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from common.messages.sim import ClockAck
from services.sim.barrier import Barrier


class FakeBus:
    def __init__(self) -> None:
        self.on_ack: Callable[[ClockAck], None] | None = None
        self.on_token: Callable[[str, bool], None] | None = None

    def subscribe(self, _topic: Any, callback: Callable[[ClockAck], None], **_: Any) -> None:
        self.on_ack = callback

    def watch(self, _key: str, callback: Callable[[str, bool], None]) -> None:
        self.on_token = callback


def barrier() -> tuple[Barrier, Callable[..., None], Callable[[str, bool], None]]:
    bus = FakeBus()
    b = Barrier(bus, deadline_s=5.0)  # type: ignore[arg-type]
    assert bus.on_ack is not None and bus.on_token is not None
    on_ack = bus.on_ack

    def ack(service: str, sim_ns: int, sender: str, roll_call: bool = False, **n: int) -> None:
        on_ack(
            ClockAck(
                service=service, sim_ns=sim_ns, sender=sender, roll_call=roll_call, published=n
            )
        )

    return b, ack, bus.on_token


def test_a_restarted_participant_is_expected_under_its_new_name_only() -> None:
    b, ack, token = barrier()
    token("sim/lockstep/nav", True)
    ack("nav", 10_000, "nav@1", cmd_vel=300)
    assert b.expect("sim@9", {"clock": 5}) == {"nav@1|cmd_vel": 300, "sim@9|clock": 5}
    token("sim/lockstep/nav", False)  # killed, and started again by the launcher
    token("sim/lockstep/nav", True)
    ack("nav", 12_000, "nav@2", cmd_vel=1)
    assert b.expect("sim@9", {}) == {"nav@2|cmd_vel": 1}


def test_the_roll_call_waits_for_every_service_up_and_its_answers_count() -> None:
    b, ack, token = barrier()
    for name in ("nav", "mission"):
        token(f"sim/lockstep/{name}", True)
    done: list[list[str]] = []
    waiting = threading.Thread(
        target=lambda: done.append(b.wait(-1, lambda: None, threading.Event(), everyone=True))
    )
    waiting.start()
    ack("nav", 0, "nav@1", roll_call=True, pose=1)
    waiting.join(0.3)
    assert waiting.is_alive()  # the mission has not answered yet
    ack("mission", 0, "mission@1", roll_call=True, plan=1, state=2)
    waiting.join(5.0)
    assert done == [[]]
    assert b.expect("sim@1", {}) == {"nav@1|pose": 1, "mission@1|plan": 1, "mission@1|state": 2}
    assert b.participants() == ["mission", "nav"]
