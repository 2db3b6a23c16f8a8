"""A call made again while nobody answers, and only then."""

from __future__ import annotations

import pytest

from common.rpc import RpcError, RpcTimeout, until_served


def test_a_call_nobody_answers_yet_is_made_again_until_it_is_answered() -> None:
    calls: list[int] = []

    def call() -> str:
        calls.append(1)
        if len(calls) < 3:
            raise RpcTimeout("no reply on phenorover/rpc/mission/cmd within 1 s")
        return "served"

    assert until_served(call, within_s=60.0, retry_s=0.0) == "served" and len(calls) == 3


def test_an_error_reply_is_raised_at_once_and_silence_only_until_the_deadline() -> None:
    calls: list[int] = []

    def refused() -> str:
        calls.append(1)
        raise RpcError("MissionStart.plan: the plan is robot 1's share")

    with pytest.raises(RpcError, match="robot 1's share"):
        until_served(refused, within_s=60.0, retry_s=0.0)
    assert len(calls) == 1

    def silent() -> str:
        raise RpcTimeout("no reply")

    with pytest.raises(RpcTimeout):
        until_served(silent, within_s=0.0, retry_s=0.0)
