from typing import Annotated

import msgspec


class PlannerConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """``workers``: planning processes (each request is computed in one, so a long
    plan never delays the answer to another request). ``cache_size``: identical
    requests are answered from a cache of this many plans. ``warm_up``: plan the
    deployment's field once at start so numba's kernels are loaded before anyone asks.
    """

    workers: Annotated[int, msgspec.Meta(ge=1, le=16)] = 2
    cache_size: Annotated[int, msgspec.Meta(ge=0)] = 32
    warm_up: bool = True
