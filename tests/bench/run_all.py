"""``make bench``: run every tests/bench/bench_*.py in its own process, each writing
its figures to runs/bench/<name>.json. Figures are reported, never asserted."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main() -> int:
    out = Path("runs/bench")
    out.mkdir(parents=True, exist_ok=True)
    failed = []
    for script in sorted(HERE.glob("bench_*.py")):
        print(f"== {script.name}", flush=True)
        r = subprocess.run(
            [sys.executable, str(script), "--json", str(out / f"{script.stem}.json")]
        )
        if r.returncode != 0:
            failed.append(script.name)
    if failed:
        print(f"failed: {', '.join(failed)}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
