from typing import Annotated

import msgspec

from services.planner.budget import PlanBudget


class PlannerConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The planning service: plans computed on request, in worker processes, within a
    budget."""

    workers: Annotated[int, msgspec.Meta(ge=1, le=16)] = 2
    """Planning processes; each request is computed in one, so a long plan never delays
    the answer to another request."""
    cache_size: Annotated[int, msgspec.Meta(ge=0)] = 32
    """Finished plans kept: an identical request is answered from them."""
    warm_up: bool = True
    """Plan the deployment's field once at start, so numba's kernels are loaded before
    anyone asks."""
    budget: PlanBudget = msgspec.field(default_factory=PlanBudget)
    """The largest field planned (:mod:`services.planner.budget`); a larger one gets a
    one-line error reply."""
    field_dirs: list[str] = msgspec.field(default_factory=list)
    """The folders a ``PlanRequest.name`` may name a field file in; empty: the shipped
    examples (``common/fields``) and the deployment's run folder. The deployment's own
    field file is always allowed; anything else gets an error reply."""
