"""Lockstep's two halves without Zenoh: the inbox that holds messages until the step
expecting them, and the participant's clock that runs each step's work in a fixed
order before acknowledging it."""

from __future__ import annotations

import threading
import time

import pytest

from common import mailbox
from common.lockstep import LockstepClock
from common.mailbox import (
    Inbox,
    Outbox,
    attachment,
    caller_attachment,
    caller_time,
    parse_attachment,
)
from common.messages.sim import SimClock


def same_key(a: str, b: str) -> bool:
    return a == b or (a.endswith("*") and b.startswith(a[:-1]))


def inbox_with(*keys: str) -> tuple[Inbox, list[int]]:
    inbox = Inbox(same_key)
    subs = [inbox.subscribed(k) for k in keys]
    inbox.take({}, 0.0)  # the first step: the subscriptions are no longer new
    return inbox, subs


def test_an_attachment_says_who_sent_a_message_and_its_number() -> None:
    assert parse_attachment(attachment("nav", 42)) == ("nav", 42)
    assert parse_attachment(b"not ours") is None
    assert parse_attachment(b"\xff\xfe") is None


def test_messages_wait_for_the_step_that_expects_them_and_run_in_a_fixed_order() -> None:
    inbox, (sub,) = inbox_with("odom")
    ran: list[str] = []
    # heard in another order than the step runs them
    inbox.deliver(sub, "odom", "base", 1, lambda: ran.append("base1"))
    inbox.deliver(sub, "odom", "sim", 1, lambda: ran.append("sim1"))
    inbox.deliver(sub, "odom", "base", 2, lambda: ran.append("base2"))
    thunks, late = inbox.take({"base|odom": 1, "sim|odom": 1}, 1.0)
    for t in thunks:
        t()
    assert ran == ["base1", "sim1"] and late == []
    # the third, published after the step's count was taken, waits for the next step
    thunks, _ = inbox.take({"base|odom": 2, "sim|odom": 1}, 1.0)
    assert len(thunks) == 1


def test_a_step_waits_for_an_expected_message_still_on_its_way() -> None:
    inbox, (sub,) = inbox_with("fix")
    inbox.deliver(sub, "fix", "gnss", 1, lambda: None)
    inbox.take({"gnss|fix": 1}, 1.0)
    late = threading.Timer(0.1, inbox.deliver, (sub, "fix", "gnss", 2, lambda: None))
    late.start()
    thunks, missing = inbox.take({"gnss|fix": 2}, 5.0)
    assert len(thunks) == 1 and missing == []


def test_a_message_that_never_comes_is_named_after_the_timeout() -> None:
    inbox, (sub,) = inbox_with("fix")
    inbox.deliver(sub, "fix", "gnss", 1, lambda: None)
    inbox.take({"gnss|fix": 1}, 1.0)
    thunks, missing = inbox.take({"gnss|fix": 3}, 0.05)
    assert thunks == [] and missing == ["gnss|fix"]


def test_the_first_message_of_a_publisher_is_waited_for_on_a_loaded_machine() -> None:
    inbox, (sub,) = inbox_with("fix")
    # never heard from gnss: its first fix still comes a scheduler's while later
    late = threading.Timer(0.3, inbox.deliver, (sub, "fix", "gnss", 1, lambda: None))
    late.start()
    thunks, missing = inbox.take({"gnss|fix": 1}, 5.0)
    assert len(thunks) == 1 and missing == []


def test_a_publisher_never_routed_to_a_subscription_is_waited_for_once(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(mailbox, "FIRST_GRACE_S", 0.2)
    inbox, _ = inbox_with("fix")
    t0 = time.monotonic()
    thunks, missing = inbox.take({"gnss|fix": 1}, 5.0)
    assert thunks == [] and missing == [] and time.monotonic() - t0 >= 0.2
    # its grace is spent: the next steps take its messages as they come, unwaited
    # (one waited for in vain would be named as missing)
    thunks, missing = inbox.take({"gnss|fix": 2}, 0.5)
    assert thunks == [] and missing == []


def test_what_was_published_before_a_subscription_is_not_waited_for() -> None:
    inbox = Inbox(same_key)
    inbox.subscribed("status")
    thunks, missing = inbox.take({"scanner|status": 7}, 5.0)
    assert thunks == [] and missing == []


def test_two_subscriptions_to_a_key_each_get_every_message() -> None:
    inbox, (a, b) = inbox_with("antennas", "antennas")
    ran: list[str] = []
    inbox.deliver(a, "antennas", "sim", 1, lambda: ran.append("a"))
    inbox.deliver(b, "antennas", "sim", 1, lambda: ran.append("b"))
    inbox.deliver(a, "antennas", "sim", 1, lambda: ran.append("again"))  # a replay
    for t in inbox.take({"sim|antennas": 1}, 1.0)[0]:
        t()
    assert ran == ["a", "b"]


def waiting_on(clock: LockstepClock, th: threading.Thread) -> None:
    """Until ``th`` waits on the clock (it says so on the clock's condition)."""
    with clock._cond:
        assert clock._cond.wait_for(lambda: th in clock._waiting, 5.0), th.name


def tick(clock: LockstepClock, step: int, ms: int) -> None:
    clock.update(SimClock(sim_ns=ms * 1_000_000, step=step))


def test_the_clock_runs_each_due_thread_in_turn_and_then_acknowledges() -> None:
    acks: list[int] = []
    acked = threading.Condition()

    def ack(t: int, roll_call: bool, published: dict[str, int]) -> None:
        with acked:
            acks.append(t)
            acked.notify_all()

    clock = LockstepClock(Inbox(same_key), ack, deadline_s=5.0)
    stop = threading.Event()
    order: list[tuple[str, int]] = []

    def worker(name: str, period_ms: int) -> None:
        t = 0
        while clock.sleep_until_ns(t * 1_000_000, stop):
            order.append((name, clock.now_ns() // 1_000_000))
            t += period_ms

    threads = [
        threading.Thread(target=worker, args=("fast", 20), daemon=True),
        threading.Thread(target=worker, args=("slow", 40), daemon=True),
    ]
    for th in threads:
        th.start()
        waiting_on(clock, th)  # registered in a known order
    for step, ms in enumerate((0, 20, 40, 60)):
        tick(clock, step, ms)
        due = ms * 1_000_000
        with acked:
            assert acked.wait_for(lambda: due in acks, 5.0)  # noqa: B023 (waited for here)
    stop.set()
    clock.close()
    assert order == [
        ("fast", 0),
        ("slow", 0),
        ("fast", 20),
        ("fast", 40),
        ("slow", 40),
        ("fast", 60),
    ]
    assert acks == [0, 20_000_000, 40_000_000, 60_000_000]


def test_an_rpc_is_served_once_the_callee_has_done_the_callers_step() -> None:
    clock = LockstepClock(Inbox(same_key), lambda *_: None, deadline_s=5.0)
    served = threading.Event()

    def serve() -> None:
        with clock.serving(40_000_000):
            served.set()

    threading.Thread(target=serve, daemon=True).start()
    tick(clock, 0, 20)
    assert not served.wait(0.2)
    tick(clock, 1, 40)
    assert served.wait(5.0)
    clock.close()


def test_a_query_carries_its_callers_time() -> None:
    assert caller_time(caller_attachment(123_000_000)) == 123_000_000
    assert caller_time(None) is None
    assert caller_time(attachment("nav", 1)) is None


def test_a_message_no_acknowledgement_has_counted_waits_for_the_step_that_does() -> None:
    # a publisher's first message, sent by an RPC's handler after its step was
    # acknowledged: taken in whenever it arrived, it would be taken at a step the
    # machine's load chose
    inbox, (sub,) = inbox_with("cmd_vel")
    inbox.deliver(sub, "cmd_vel", "nav", 1, lambda: None)
    thunks, missing = inbox.take({"sim|clock": 4}, 1.0)
    assert thunks == [] and missing == []
    thunks, missing = inbox.take({"sim|clock": 5, "nav|cmd_vel": 1}, 1.0)
    assert len(thunks) == 1 and missing == []


class Acks:
    """A participant's acknowledgements, as the simulator would hear them."""

    def __init__(self) -> None:
        self.got: list[tuple[int, bool, dict[str, int]]] = []
        self._cond = threading.Condition()

    def __call__(self, t: int, roll_call: bool, published: dict[str, int]) -> None:
        with self._cond:
            self.got.append((t, roll_call, dict(published)))
            self._cond.notify_all()

    def wait(self, n: int) -> list[tuple[int, bool, dict[str, int]]]:
        with self._cond:
            assert self._cond.wait_for(lambda: len(self.got) >= n, 5.0), self.got
            return list(self.got)


def test_a_tick_sent_again_is_acknowledged_again_not_done_again() -> None:
    acks, counts = Acks(), {"odom": 1}
    inbox, (sub,) = inbox_with("fix")
    clock = LockstepClock(inbox, acks, deadline_s=5.0, counts=lambda: dict(counts))
    runs: list[int] = []
    stop = threading.Event()

    def worker() -> None:
        while clock.sleep_until_ns(0, stop):  # asks for no time at all: due at every step
            runs.append(clock.now_ns())
            counts["odom"] += 1
            if clock.sleep_until_ns(1_000_000_000, stop):
                return

    th = threading.Thread(target=worker, daemon=True)
    th.start()
    waiting_on(clock, th)
    tick(clock, 0, 0)
    acks.wait(1)
    inbox.deliver(sub, "fix", "gnss", 1, lambda: runs.append(-1))
    tick(clock, 0, 0)  # the same tick again (its acknowledgement was late)
    got = acks.wait(2)
    assert runs == [0] and got == [(0, False, {"odom": 2}), (0, False, {"odom": 2})]
    stop.set()
    clock.close()


def test_a_roll_call_is_only_answered() -> None:
    acks, begun = Acks(), threading.Event()
    inbox, (sub,) = inbox_with("fix")
    clock = LockstepClock(inbox, acks, deadline_s=5.0, counts=lambda: {"plan": 2}, begin=begun.set)
    stop = threading.Event()
    ran: list[str] = []

    def worker() -> None:
        if clock.sleep_until_ns(0, stop):
            ran.append("thread")

    threading.Thread(target=worker, daemon=True).start()
    inbox.deliver(sub, "fix", "gnss", 1, lambda: ran.append("fix"))
    clock.update(SimClock(sim_ns=0, step=0, roll_call=True))
    assert acks.wait(1) == [(0, True, {"plan": 2})]
    # what waited for the world was sent; nothing ran, the clock has not started, and
    # its RPCs carry no time yet
    assert begun.is_set() and ran == []
    assert not clock.wait_started(0.0) and clock.stamp() is None
    tick(clock, 0, 0)
    acks.wait(2)
    assert clock.stamp() == 0
    stop.set()
    clock.close()


class FakePublisher:
    def __init__(self) -> None:
        self.sent: list[tuple[bytes, bytes]] = []

    def put(self, payload: bytes, attachment: bytes) -> None:
        self.sent.append((payload, attachment))


def test_an_outbox_holds_a_participants_messages_until_its_first_step() -> None:
    pub = FakePublisher()
    out = Outbox("scanner", hold=True)
    out.send(pub, "status", b"idle")  # type: ignore[arg-type]
    assert pub.sent == [] and out.counts() == {}
    out.begin()
    out.send(pub, "status", b"scanning")  # type: ignore[arg-type]
    me = out.sender
    assert pub.sent == [(b"idle", attachment(me, 1)), (b"scanning", attachment(me, 2))]
    assert out.counts() == {"status": 2}
    # the world's own outbox holds nothing
    world = Outbox("sim", hold=False)
    world.send(pub, "clock", b"t")  # type: ignore[arg-type]
    assert pub.sent[-1] == (b"t", attachment(world.sender, 1))


def test_a_restarted_publisher_is_heard_from_its_first_message() -> None:
    # nav killed after 300 commands and started again: its numbers start at 1 again,
    # under a name of its own, so no subscriber takes them for replays of the old ones
    before, after = Outbox("nav", hold=False), Outbox("nav", hold=False)
    assert before.sender != after.sender and before.sender.startswith("nav@")
    inbox, (sub,) = inbox_with("cmd_vel")
    inbox.deliver(sub, "cmd_vel", before.sender, 300, lambda: None)
    inbox.take({f"{before.sender}|cmd_vel": 300}, 1.0)
    ran: list[int] = []
    inbox.deliver(sub, "cmd_vel", after.sender, 1, lambda: ran.append(1))
    thunks, missing = inbox.take({f"{after.sender}|cmd_vel": 1}, 1.0)
    for t in thunks:
        t()
    assert ran == [1] and missing == []
