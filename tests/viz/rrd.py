"""Read an .rrd back with rerun's own command-line tools."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

RERUN = Path(sys.executable).with_name("rerun")


def verify(path: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(RERUN), "rrd", "verify", str(path)], capture_output=True, text=True, timeout=120
    )


def entity_paths(path: Path) -> set[str]:
    """The entity paths of a recording, from ``rerun rrd stats``."""
    r = subprocess.run(
        [str(RERUN), "rrd", "stats", str(path)], capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    start = lines.index("Num chunks per entity") + 2
    out = set()
    for line in lines[start:]:
        if not line.strip():
            break
        out.add(line.rsplit(":", 1)[0].strip())
    return out
