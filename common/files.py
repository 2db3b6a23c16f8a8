"""Writing a file whole or not at all, and reading one of bounded size."""

from __future__ import annotations

import contextlib
import math
import os
import stat
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any


@contextlib.contextmanager
def atomic_path(path: Path, durable: bool = False) -> Iterator[Path]:
    """Yield a temporary to write ``path``'s new content to; on a clean exit it is
    renamed onto ``path``, so a reader (or a run interrupted half way) sees the
    previous file or the new one, never half of one; on an exception it is removed.
    The temporary sits beside ``path`` (one file system, so the rename is atomic),
    hidden, and keeps the suffix by which pye57, laspy and matplotlib pick the
    format; a leftover (or a planted symlink) there is removed, not written through.
    ``durable``: the file and its folder are synced to disk, so that a power cut right
    after keeps the new file (a scanner's card, a simulator's world)."""
    tmp = path.with_name(f".{path.stem}.part{path.suffix}")
    tmp.unlink(missing_ok=True)
    try:
        yield tmp
        if durable:
            _fsync(tmp)
        os.replace(tmp, path)
        if durable:
            _fsync(path.parent)
    finally:
        tmp.unlink(missing_ok=True)


def atomic_write(path: Path, write: Callable[[Path], object], durable: bool = False) -> None:
    """``write(tmp)``, then ``tmp`` renamed onto ``path`` (:func:`atomic_path`)."""
    with atomic_path(path, durable) as tmp:
        write(tmp)


def write_atomic(path: Path, data: bytes, durable: bool = False) -> None:
    """``data`` written to ``path`` whole or not at all (:func:`atomic_path`)."""
    with atomic_path(path, durable) as tmp:
        tmp.write_bytes(data)


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def read_regular(path: Path, limit: int, what: str) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes: a FIFO or /dev/zero
    would never end, and a huge file would fill the memory. Raises ValueError (one
    line naming ``path`` and, for a file too large, ``what`` it is) and OSError."""
    st = path.stat()
    if not stat.S_ISREG(st.st_mode):
        raise ValueError(f"{path}: not a regular file")
    if st.st_size > limit:
        raise ValueError(f"{path}: {st.st_size:,} bytes, more than the {limit:,} {what} may have")
    return path.read_bytes()


def finite(v: Any) -> Any:
    """``v`` (nested dicts, lists, tuples) with NaN and infinities as None: JSON has no
    NaN, so what goes into a JSON file is written with ``allow_nan=False``."""
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, dict):
        return {k: finite(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [finite(x) for x in v]
    return v
