"""Where the simulator may write.

The render RPC names the E57 file to write (the scanner's card, as a real FARO writes
its own card). A request is a message from the network, so its path is resolved
(``..`` and symlinks followed) and must lie under the configured scan folder, each
name in it matching :data:`common.messages.core.FileName`'s pattern; anything else is
refused with a line naming ``RenderRequest.path``. The file itself is written whole
or not at all by :func:`common.pointcloud.write_e57` (durable).
"""

from __future__ import annotations

import re
import typing
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
