"""A call to a service that is there but slow times out as a call nobody answers
does (RpcTimeout, which the mission retries), not as the service's error; and a call
from a service in lockstep waits as long as the lockstep would for the callee,
however short the timeout it asks for: on a loaded machine an answer may take
seconds of wall time, and a call that timed out would be retried and logged, so the
same seed would give another mission log."""

from __future__ import annotations

import threading

import pytest

from common import keys
from common.lockstep import LockstepClock
from common.mailbox import Inbox
from common.messages.system import Ping, Pong
from common.transport import RpcTimeout
from tests.conftest import client


def test_a_lockstep_call_outwaits_a_slow_callee_and_a_free_one_does_not(
    router_endpoint: str,
) -> None:
    release = threading.Event()
    rpc = keys.PING.at(service="slow")

    def slow(_: Ping) -> Pong:
        release.wait(10.0)  # the callee of a loaded machine: answers when let
        return Pong(service="slow")

    with client(router_endpoint, "slow") as server, client(router_endpoint, "caller") as caller:
        server.serve(rpc, slow)
        with pytest.raises(RpcTimeout):
            caller.call(rpc, Ping(), timeout=0.2)
        release.set()  # the first call's answer is late, not lost

        release.clear()
        clock = LockstepClock(Inbox(lambda a, b: a == b), lambda *_: None, deadline_s=10.0)
        caller.use_lockstep(Inbox(lambda a, b: a == b), clock)
        answer: list[Pong] = []
        t = threading.Thread(target=lambda: answer.append(caller.call(rpc, Ping(), timeout=0.2)))
        t.start()
        t.join(1.0)  # well past the asked 0.2 s, the call still waits
        assert t.is_alive() and not answer
        release.set()
        t.join(10.0)
        assert answer and answer[0].service == "slow"
        clock.close()
