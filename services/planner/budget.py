"""How big a field the planner takes on, checked before any visibility work.

A candidate is tested against the cells of the plots within the scanner's range, and
the visibility table holds the pairs it sees among them: the cost of a plan grows
with those *pairs in range*, summed over the candidates (cast one by one; a regular
field casts one candidate and moves its table to the others, :mod:`.lattice`, but
its table is as large). Estimated from up to 256 candidates spread over the field:

- ENGR, SPL: 3.3e5 and 1.1e5; well under a second.
- 40 rows x 50 plots (the planning benchmark's largest field): 1.5e8 pairs in
  range, 5.8 M seen.
- 100 x 100 plots: 1.1e9 in range, 36 M seen.
- 140 x 140 plots: 2.4e9 in range.

The default budget, 2e9, takes the 100 x 100 field and refuses fields beyond about
twice its size with a line saying why, in the service before anything is sent to a
worker. Workers also run under a hard memory limit (``RLIMIT_DATA``), so an
estimate that is wrong ends in an error reply rather than in the machine swapping.
"""

from __future__ import annotations

import dataclasses
import resource
from typing import Annotated

import msgspec
import numpy as np

from common.field import Field, FieldError, ScannerModel
from services.planner.raycast import in_range

DEFAULT_MAX_CELL_CANDIDATES = 2_000_000_000
_SAMPLE = 256  # candidates the estimate looks at
DEFAULT_WORKER_MEMORY_MB = 4096


class PlanBudget(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The most a plan may cost; a field over it is refused before it is planned."""

    max_cell_candidates: Annotated[int, msgspec.Meta(gt=0)] = DEFAULT_MAX_CELL_CANDIDATES
    """The most cell-candidate pairs within the scanner's range a plan may need."""
    worker_memory_mb: Annotated[int, msgspec.Meta(ge=0)] = DEFAULT_WORKER_MEMORY_MB
    """The data-segment limit of each planning worker, MB (0: none)."""


class OverBudget(FieldError):
    """The field is larger than the planner's budget; one line, naming the numbers."""


@dataclasses.dataclass(frozen=True)
class Estimate:
    """What a plan of a field will cost: ``pairs``, the cell-candidate pairs within
    the scanner's range, and the bytes of a visibility table holding them all (int32
    candidate, cell and hits and a float32 range each), an upper bound on the table."""

    cells: int
    candidates: int
    pairs: int
    table_bytes: int


def estimate(field: Field, reach: float) -> Estimate:
    """The pairs within ``reach`` metres (the scanner's range), from up to 256
    candidates spread over the field: each one's plots whose box comes within reach."""
    n = field.n_candidates
    rows = np.unique(np.linspace(0, n - 1, min(n, _SAMPLE)).round().astype(np.int64))
    near = in_range(field.cand_xy[rows], field.plot_boxes, reach)
    per = (near @ np.diff(field.cell_offset)).mean() if len(rows) else 0.0
    pairs = int(np.rint(per * n))
    return Estimate(field.n_cells, n, pairs, 16 * pairs)


def check(field: Field, budget: PlanBudget, reach: float = ScannerModel().max_range) -> Estimate:
    """The estimate of ``field`` for a scanner reaching ``reach`` metres; raises
    :class:`OverBudget` when it exceeds ``budget``."""
    e = estimate(field, reach)
    if e.pairs > budget.max_cell_candidates:
        raise OverBudget(
            f"field {field.name!r}: {e.cells:,} cells, {e.candidates:,} candidates, about "
            f"{e.pairs:.2g} cell-candidate pairs within the scanner's {reach:g} m (a "
            f"visibility table of up to {e.table_bytes / 2**30:.1f} GiB), more than the "
            f"planner's budget of {budget.max_cell_candidates:.2g} ([services.planner.budget] "
            "max_cell_candidates)"
        )
    return e


def limit_memory(megabytes: int) -> None:
    """In a worker process: cap its data segment (heap and private mappings) so an
    allocation beyond ``megabytes`` raises MemoryError; 0 leaves it unlimited."""
    if megabytes > 0:
        limit = megabytes << 20
        _, hard = resource.getrlimit(resource.RLIMIT_DATA)
        if hard != resource.RLIM_INFINITY:
            limit = min(limit, hard)
        resource.setrlimit(resource.RLIMIT_DATA, (limit, hard))
