"""Writing a file whole or not at all."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path


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
