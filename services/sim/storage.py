"""Where the simulator may write, and writing there so a reader never sees half a file.

The render RPC names the E57 file to write (the scanner's card, as a real FARO writes
its own card). A request is a message from the network, so its path is resolved
(``..`` and symlinks followed) and must lie under the configured scan folder, each
name in it matching :data:`common.messages.core.FileName`'s pattern; anything else is
refused with a line naming ``RenderRequest.path``.

Files are written as ``<name>.tmp`` in the same folder, flushed to disk and renamed
over the final name: a crash leaves the old file or none, never a truncated one.
"""

from __future__ import annotations

import contextlib
import os
import re
import typing
from collections.abc import Iterator
from pathlib import Path

import msgspec

from common.messages.core import FileName

# the one pattern of a file name in messages, taken from its type
_NAME = re.compile(
    next(
        m.pattern
        for m in typing.get_args(FileName)[1:]
        if isinstance(m, msgspec.Meta) and m.pattern is not None
    )
)


class PathRefused(ValueError):
    """A requested path is outside the allowed folder or has a bad name; one line."""


def confine(path: str, root: Path, suffix: str, field: str) -> Path:
    """``path`` resolved, when it is a ``suffix`` file under ``root`` whose every name
    below ``root`` matches FileName; else PathRefused naming ``field``."""
    base = root.resolve()
    p = Path(path)
    target = (p if p.is_absolute() else base / p).resolve()
    if target.suffix != suffix:
        raise PathRefused(f"{field}: {path!r} is not a {suffix} file")
    if not target.is_relative_to(base):
        raise PathRefused(f"{field}: {path!r} is outside the scan folder {base}")
    bad = [n for n in target.relative_to(base).parts if not _NAME.fullmatch(n)]
    if bad:
        raise PathRefused(f"{field}: {path!r}: {bad[0]!r} is not an allowed file name")
    return target


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(path: Path, durable: bool = True) -> Iterator[Path]:
    """Yield ``<path>.tmp`` to write to; on a clean exit it is fsynced (``durable``)
    and renamed to ``path`` (the folder synced too), on an exception removed."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.unlink(missing_ok=True)  # a leftover, or a planted symlink, is not written through
    try:
        yield tmp
        if durable:
            _fsync(tmp)
        os.replace(tmp, path)
        if durable:
            _fsync(path.parent)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_atomic(path: Path, data: bytes, durable: bool = True) -> None:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_path`)."""
    with atomic_path(path, durable) as tmp:
        tmp.write_bytes(data)
