from typing import Annotated

import msgspec

from services.planner.budget import PlanBudget


class PlannerConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """``workers``: planning processes (each request is computed in one, so a long
    plan never delays the answer to another request). ``cache_size``: identical
    requests are answered from a cache of this many plans. ``warm_up``: plan the
    deployment's field once at start so numba's kernels are loaded before anyone asks.
    ``budget``: the largest field planned (see :mod:`services.planner.budget`); a
    larger one gets an error reply. ``field_dirs``: the folders a ``PlanRequest.name``
    may name a field file in; empty (default): the shipped examples
    (``common/fields``) and the deployment's run folder. The deployment's own field
    file is always allowed; anything else gets an error reply.
    """

    workers: Annotated[int, msgspec.Meta(ge=1, le=16)] = 2
    cache_size: Annotated[int, msgspec.Meta(ge=0)] = 32
    warm_up: bool = True
    budget: PlanBudget = msgspec.field(default_factory=PlanBudget)
    field_dirs: list[str] = msgspec.field(default_factory=list)
