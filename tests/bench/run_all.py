"""``make bench``: run every tests/bench/bench_*.py in its own process, each writing
its figures to docs/bench/<name>.json through phenorover.eval.results. Figures are
reported, never asserted; a benchmark that fails (an experiment failed, or it died)
makes this exit 1. A benchmark that died before writing its JSON gets one that says
so, never the figures of an earlier run. `make results` renders docs/results.md."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from phenorover.eval.results import BENCH_DIR, Bench

HERE = Path(__file__).resolve().parent


def run(script: Path, out: Path) -> int:
    """Run one benchmark; its exit status."""
    path = out / f"{script.stem}.json"
    started = time.time()
    r = subprocess.run([sys.executable, str(script), "--json", str(path)])
    if r.returncode != 0 and (not path.exists() or path.stat().st_mtime < started):
        bench = Bench(script.stem)
        bench.fail(script.stem, f"{script.name} exited {r.returncode} before writing its results")
        bench.finish(path)
    return r.returncode


def main() -> int:
    out = BENCH_DIR
    out.mkdir(parents=True, exist_ok=True)
    failed = []
    for script in sorted(HERE.glob("bench_*.py")):
        print(f"== {script.name}", flush=True)
        if run(script, out) != 0:
            failed.append(script.name)
    if failed:
        print(f"failed: {', '.join(failed)}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
