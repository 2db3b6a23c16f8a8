"""What a deployment's services cost in CPU, per simulated second.

Read from Linux's ``/proc/PID/stat``: user and system time of the process and of the
children it has waited for, so a service's own jobs (the mission's registration run)
count as its own. A zombie (exited, not yet reaped) still shows its final times,
which is how a launcher keeps the CPU of a service it restarts. Elsewhere than on
Linux nothing is measured.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

from common.files import write_atomic

_TICK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def cpu_seconds(pid: int) -> float | None:
    """CPU seconds used by process ``pid`` and its waited-for children; None when it
    cannot be read (no such process, not Linux)."""
    try:
        return parse_stat(Path(f"/proc/{pid}/stat").read_text())
    except OSError:
        return None


def parse_stat(text: str) -> float | None:
    """CPU seconds from the text of a ``/proc/PID/stat``; None when it is not one."""
    # the command name (field 2) may hold spaces and parentheses: the fields are
    # counted from the last ')'; utime, stime, cutime, cstime are fields 14-17
    try:
        fields = text[text.rindex(")") + 2 :].split()
        if len(fields) < 15:
            return None
        return sum(int(f) for f in fields[11:15]) / _TICK
    except (ValueError, IndexError):
        return None


@dataclasses.dataclass(frozen=True)
class Mark:
    """A moment of a deployment: wall (monotonic s), sim (s) and CPU (s) per service."""

    wall_s: float
    sim_s: float
    cpu_s: dict[str, float]


@dataclasses.dataclass(frozen=True)
class CpuUse:
    """CPU per service between two marks, against the simulated and the wall time."""

    sim_s: float
    wall_s: float
    cpu_s: dict[str, float]

    @classmethod
    def between(cls, a: Mark, b: Mark) -> CpuUse:
        cpu = {n: max(b.cpu_s[n] - a.cpu_s.get(n, 0.0), 0.0) for n in b.cpu_s}
        return cls(b.sim_s - a.sim_s, b.wall_s - a.wall_s, cpu)

    def per_sim_s(self) -> dict[str, float]:
        """CPU seconds per simulated second, per service (empty over no sim time)."""
        if self.sim_s <= 0:
            return {}
        return {n: c / self.sim_s for n, c in self.cpu_s.items()}

    def line(self) -> str:
        """One line, the dearest service first."""
        rates = self.per_sim_s()
        if not rates:
            return "cpu per simulated second: no simulated time went by"
        parts = ", ".join(f"{n} {r:.3f}" for n, r in sorted(rates.items(), key=lambda x: -x[1]))
        return (
            f"cpu per simulated second: {parts} (total {sum(rates.values()):.3f}; "
            f"{self.sim_s:.0f} s simulated in {self.wall_s:.0f} s of wall time)"
        )

    def write(self, path: Path) -> None:
        """``path`` as JSON: sim_s, wall_s, cpu_s and cpu_per_sim_s per service."""
        body = dataclasses.asdict(self) | {"cpu_per_sim_s": self.per_sim_s()}
        text = json.dumps(body, indent=1, sort_keys=True) + "\n"
        write_atomic(path, text.encode())


def read_use(path: Path) -> CpuUse | None:
    """The :class:`CpuUse` :meth:`CpuUse.write` wrote; None when missing or unreadable."""
    try:
        d = json.loads(path.read_text())
        cpu = {str(k): float(v) for k, v in d["cpu_s"].items()}
        return CpuUse(float(d["sim_s"]), float(d["wall_s"]), cpu)
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None
