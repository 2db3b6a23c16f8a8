"""The wire encoding of every message: msgpack by msgspec, one reused Encoder and one
Decoder per type; and the count of what failed to decode. Zenoh-free, so tests and
tools can encode a message without a session."""

from __future__ import annotations

import threading
import time
from typing import Any

import msgspec
import numpy as np


def _enc_hook(obj: Any) -> Any:
    # numpy scalars reach messages from every numeric core; send them as Python numbers
    if isinstance(obj, np.generic):
        return obj.item()
    raise NotImplementedError(f"cannot encode objects of type {type(obj).__name__}")


_ENCODER = msgspec.msgpack.Encoder(enc_hook=_enc_hook)
_DECODERS: dict[Any, msgspec.msgpack.Decoder[Any]] = {}
_DECODERS_LOCK = threading.Lock()


def encode(msg: Any) -> bytes:
    return _ENCODER.encode(msg)


def decode(data: bytes, type_: Any) -> Any:
    """Decode ``data`` as ``type_``; raises msgspec.DecodeError/ValidationError."""
    dec = _DECODERS.get(type_)
    if dec is None:
        with _DECODERS_LOCK:
            dec = _DECODERS.setdefault(type_, msgspec.msgpack.Decoder(type_))
    return dec.decode(data)


class DecodeStats:
    """Counts of failures per key (messages dropped because they did not decode, or
    callbacks that raised), with the latest one as a line and its wall time."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.by_key: dict[str, int] = {}
        self.last_error = ""
        self.last_ns = 0  # wall time of the latest failure, 0 before any

    @property
    def total(self) -> int:
        with self._lock:
            return sum(self.by_key.values())

    def record(self, key: str, reason: str) -> bool:
        """Count one failure; True when it is the first on this key (log it then)."""
        with self._lock:
            n = self.by_key.get(key, 0)
            self.by_key[key] = n + 1
            self.last_error = f"{key}: {reason}"
            self.last_ns = time.time_ns()
            return n == 0
