"""Queries over the bus: a handler's answer (its errors as one-line replies) and the
first reply to a call. :class:`common.transport.Bus` serves and calls with them."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from contextlib import AbstractContextManager, nullcontext
from typing import Any, TypeVar

import msgspec
import zenoh

from common.codec import decode, encode
from common.keys import Rpc

Q = TypeVar("Q")
R = TypeVar("R")


class RpcError(RuntimeError):
    """The service answered a query with an error (its text says what was wrong)."""


class RpcTimeout(RpcError):
    """No service answered a query within its timeout."""


class RequestError(ValueError):
    """Raised by an RPC handler to answer with an error reply instead of a result."""


def until_served(call: Callable[[], R], within_s: float, retry_s: float = 0.5) -> R:
    """``call()``, made again while nobody answers it (RpcTimeout: a service that is
    alive but has not declared its queryable yet, or one restarting) for up to
    ``within_s`` seconds, ``retry_s`` apart; an error reply is raised at once."""
    deadline = time.monotonic() + within_s
    while True:
        try:
            return call()
        except RpcTimeout:
            if time.monotonic() + retry_s > deadline:
                raise
            time.sleep(retry_s)


def answer(
    query: zenoh.Query,
    rpc: Rpc[Q, R],
    handler: Callable[[Q], R],
    name: str,
    dropped: Callable[[str, Exception], None],
    failed: Callable[[str, str], None],
    serving: AbstractContextManager[Any] | None = None,
) -> None:
    """Answer ``query`` with ``handler(request)`` (inside ``serving``, lockstep's
    turn, when given). A request that fails to decode (``dropped``), or a handler
    raising RequestError, gets an error reply with a one-line reason; other
    exceptions are counted (``failed``) and answered as internal errors of ``name``."""
    key = str(query.key_expr)
    try:
        payload = query.payload.to_bytes() if query.payload is not None else b""
        try:
            req = decode(payload, rpc.request)
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            dropped(key, exc)
            query.reply_err(f"bad request on {key}: {exc}".encode())
            return
        try:
            with serving if serving is not None else nullcontext():
                rep = handler(req)
        except RequestError as exc:
            query.reply_err(f"{exc}".encode())
            return
        except Exception as exc:
            failed(key, "handler")
            query.reply_err(f"internal error in {name}: {exc!r}".encode())
            return
        query.reply(query.key_expr, encode(rep))
    finally:
        query.drop()


# the error reply Zenoh gives a query its queryable did not answer in time (none of
# our services says this: their error replies name the request or the service)
ZENOH_TIMEOUT = "Timeout"


def good_replies(
    replies: Iterable[zenoh.Reply], rpc: Rpc[Q, R], dropped: Callable[[str, Exception], None]
) -> list[R]:
    """Every good reply of ``replies`` to a query on ``rpc``, in order; error replies
    are left out and undecodable ones given to ``dropped``."""
    out: list[R] = []
    for reply in replies:
        if reply.ok is None:
            continue
        try:
            out.append(decode(reply.ok.payload.to_bytes(), rpc.reply))
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            dropped(rpc.key, exc)
    return out


def first_reply(replies: Iterable[zenoh.Reply], rpc: Rpc[Q, R], timeout: float) -> R:
    """The first of ``replies`` to a call on ``rpc``. Raises RpcError with the
    service's reason on an error reply, RpcTimeout when there is none."""
    for reply in replies:
        if reply.ok is not None:
            try:
                result: R = decode(reply.ok.payload.to_bytes(), rpc.reply)
            except (msgspec.DecodeError, msgspec.ValidationError) as exc:
                raise RpcError(f"undecodable reply on {rpc.key}: {exc}") from exc
            return result
        err = reply.err
        text = err.payload.to_bytes().decode(errors="replace") if err else "error"
        if text == ZENOH_TIMEOUT:  # a service that is there but slow: silent, as none
            break
        raise RpcError(text)
    raise RpcTimeout(f"no reply on {rpc.key} within {timeout:g} s")
