"""A test service built on the real runner: it talks on test-only keys.

- talker: publishes ``count`` Blobs of ``size`` bytes on a bulk topic, then idles;
  serves an Echo RPC (which rejects text "bad" with a RequestError).
- listener: checks each Blob's digest and reports it on ``test/received``.
- ``hang_on_stop``: never returns from ``run`` (a service stuck in its shutdown).
"""

from __future__ import annotations

import hashlib
import threading
import time
from typing import Annotated, Literal

import msgspec

from common.keys import Rpc, Topic
from common.messages.core import Message
from common.service import Context, run
from common.transport import RequestError


class Blob(Message, frozen=True, kw_only=True):
    seq: Annotated[int, msgspec.Meta(ge=0)]
    digest: str
    data: bytes


class Received(Message, frozen=True, kw_only=True):
    seq: int
    size: int
    ok: bool


class Echo(Message, frozen=True, kw_only=True):
    text: str


BLOB = Topic("phenorover/test/blob", Blob, bulk=True)
RECEIVED = Topic("phenorover/test/received", Received)
ECHO = Rpc[Echo, Echo]("phenorover/test/echo", Echo, Echo)


class ProbeConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    role: Literal["talker", "listener"] = "listener"
    size: Annotated[int, msgspec.Meta(ge=0)] = 1000
    count: Annotated[int, msgspec.Meta(ge=0)] = 0
    period_s: float = 0.2
    hang_on_stop: bool = False


class Probe:
    def __init__(self, ctx: Context, cfg: ProbeConfig) -> None:
        self.ctx, self.cfg = ctx, cfg
        if cfg.role == "talker":
            self.pub = ctx.bus.publisher(BLOB)
            ctx.bus.serve(ECHO, self.echo)
        else:
            self.rec = ctx.bus.publisher(RECEIVED)
            ctx.bus.subscribe(BLOB, self.on_blob)

    def echo(self, req: Echo) -> Echo:
        if req.text == "bad":
            raise RequestError("Echo.text: 'bad' is not allowed")
        return Echo(text=req.text)

    def on_blob(self, b: Blob) -> None:
        ok = hashlib.sha256(b.data).hexdigest() == b.digest
        self.rec.put(Received(seq=b.seq, size=len(b.data), ok=ok))

    def run(self, stop: threading.Event) -> None:
        if self.cfg.role == "talker":
            data = bytes(range(256)) * (self.cfg.size // 256) + b"x" * (self.cfg.size % 256)
            digest = hashlib.sha256(data).hexdigest()
            for seq in range(self.cfg.count):
                if stop.wait(self.cfg.period_s):
                    return
                self.pub.put(Blob(seq=seq, digest=digest, data=data))
        stop.wait()
        while self.cfg.hang_on_stop:
            time.sleep(1.0)


if __name__ == "__main__":
    run("probe", ProbeConfig, Probe)
