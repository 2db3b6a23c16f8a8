"""Writing a file whole or not at all, and reading one of bounded size."""

from __future__ import annotations

import math
import os
import stat
from collections.abc import Callable
from pathlib import Path
from typing import Any


def atomic_write(path: Path, write: Callable[[Path], object]) -> None:
    """``write(tmp)`` then rename onto ``path``, so a reader (or a run interrupted
    half way) sees the previous file or the new one, never half of one. The temporary
    sits beside ``path`` (one file system, so the rename is atomic) and keeps its
    suffix, by which pye57, laspy and matplotlib pick the format."""
    tmp = path.with_name(f".{path.stem}.part{path.suffix}")
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


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
