"""How big a field the planner takes on, checked before any visibility work.

The cost of a plan grows with cells x candidates: every candidate location is tested
against every cell (the exact mode's rays, the grid mode's cell lookups), and the
visibility table is cut from dense (candidates x cells) buffers. Measured on the
2-core development machine (exact visibility, exact cover):

- ENGR, SPL: 77 x 2,160 = 1.7e5; well under a second.
- 40 rows x 50 plots (the planning benchmark's largest field): 2,091 x 144,000 = 3.0e8; 28 s in all,
  5.8 M visible pairs, 0.7 GB peak.
- 100 x 100 plots: 10,201 x 720,000 = 7.3e9; 137 s and 5.0 GB.

The default budget, 1e9, takes fields about three times the benchmark's size and
refuses the 100 x 100 one with a line saying why, in the service before anything is
sent to a worker. Workers also run under a hard memory limit (``RLIMIT_DATA``), so an
estimate that is wrong ends in an error reply rather than in the machine swapping.
"""

from __future__ import annotations

import dataclasses
import resource
from typing import Annotated

import msgspec

from common.field import Field, FieldError

DEFAULT_MAX_CELL_CANDIDATES = 1_000_000_000
DEFAULT_WORKER_MEMORY_MB = 4096


class PlanBudget(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """``max_cell_candidates``: the largest cells x candidates a plan may need.
    ``worker_memory_mb``: the data-segment limit of each planning worker (0: none)."""

    max_cell_candidates: Annotated[int, msgspec.Meta(gt=0)] = DEFAULT_MAX_CELL_CANDIDATES
    worker_memory_mb: Annotated[int, msgspec.Meta(ge=0)] = DEFAULT_WORKER_MEMORY_MB


class OverBudget(FieldError):
    """The field is larger than the planner's budget; one line, naming the numbers."""


@dataclasses.dataclass(frozen=True)
class Estimate:
    """What a plan of a field will cost: ``pairs`` = cells x candidates, and the bytes
    of a dense (candidates x cells) visibility table of int32 hits + float32 ranges,
    which the planner never holds whole but would if it were not cut into chunks."""

    cells: int
    candidates: int
    pairs: int
    dense_table_bytes: int


def estimate(field: Field) -> Estimate:
    pairs = field.n_cells * field.n_candidates
    return Estimate(field.n_cells, field.n_candidates, pairs, 8 * pairs)


def check(field: Field, budget: PlanBudget) -> Estimate:
    """The estimate of ``field``; raises :class:`OverBudget` when it exceeds ``budget``."""
    e = estimate(field)
    if e.pairs > budget.max_cell_candidates:
        raise OverBudget(
            f"field {field.name!r}: {e.cells:,} cells x {e.candidates:,} candidates = "
            f"{e.pairs:.2g} cell-candidate pairs (a dense visibility table of "
            f"{e.dense_table_bytes / 2**30:.1f} GiB), more than the planner's budget of "
            f"{budget.max_cell_candidates:.2g} ([services.planner.budget] max_cell_candidates)"
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
