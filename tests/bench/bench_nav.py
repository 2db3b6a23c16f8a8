"""Navigation benchmark: the paper's three experiments (``phenorover nav-test``) on the
simulated ENGR field with the default error models; figures are reported, never
asserted. Targets: border mean cross-track <= 2.0 cm and >= 90 % below 5 cm;
serpentine mean <= 3.0 cm; stationary mean distance to the planned point <= 0.5 cm
and heading error <= 0.1 deg.

    python tests/bench/bench_nav.py [--json OUT] [--rtf 10]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--rtf", type=float, default=10.0)
    args = ap.parse_args()
    results = {}
    with tempfile.TemporaryDirectory() as d:
        for exp in ("border", "serpentine", "stationary"):
            out = Path(d) / exp
            r = subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "phenorover",
                    "--log-level",
                    "warning",
                    "nav-test",
                    exp,
                    "--rtf",
                    str(args.rtf),
                    "--out",
                    str(out),
                ],
                capture_output=True,
                text=True,
            )
            if r.returncode != 0 or not (out / "stats.json").exists():
                print(f"{exp}: failed: {r.stderr.strip().splitlines()[-1:]}")
                results[exp] = {"failed": True}
                continue
            results[exp] = json.loads((out / "stats.json").read_text())
            print(f"{exp}: {json.dumps(results[exp])}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
