"""Hypothesis strategies derived from msgspec type info, so every message type gets a
round-trip test without a hand-written strategy."""

from __future__ import annotations

import math
from typing import Any

import msgspec
import msgspec.inspect as mi
from hypothesis import strategies as st


def strategy_for(t: mi.Type) -> st.SearchStrategy[Any]:
    if isinstance(t, mi.BoolType):
        return st.booleans()
    if isinstance(t, mi.IntType):
        lo = t.ge if t.ge is not None else (t.gt + 1 if t.gt is not None else -(2**40))
        hi = t.le if t.le is not None else (t.lt - 1 if t.lt is not None else 2**40)
        return st.integers(lo, hi)
    if isinstance(t, mi.FloatType):
        flo: float = t.ge if t.ge is not None else (t.gt if t.gt is not None else -1e9)
        fhi: float = t.le if t.le is not None else (t.lt if t.lt is not None else 1e9)
        return st.floats(flo, fhi, exclude_min=t.gt is not None, exclude_max=t.lt is not None)
    if isinstance(t, mi.StrType):
        if t.pattern is not None:
            return st.from_regex(t.pattern, fullmatch=True)
        lo = t.min_length or 0
        return st.text(min_size=lo, max_size=max(lo, min(t.max_length or 20, 20)))
    if isinstance(t, mi.BytesType):
        return st.binary(max_size=64)
    if isinstance(t, mi.DateType):
        return st.dates()
    if isinstance(t, mi.NoneType):
        return st.none()
    if isinstance(t, mi.EnumType):
        return st.sampled_from(list(t.cls))
    if isinstance(t, mi.LiteralType):
        return st.sampled_from(list(t.values))
    if isinstance(t, (mi.ListType, mi.VarTupleType)):
        inner = st.lists(strategy_for(t.item_type), max_size=4)
        return inner if isinstance(t, mi.ListType) else inner.map(tuple)
    if isinstance(t, mi.TupleType):
        return st.tuples(*(strategy_for(i) for i in t.item_types))
    if isinstance(t, mi.DictType):
        return st.dictionaries(strategy_for(t.key_type), strategy_for(t.value_type), max_size=3)
    if isinstance(t, mi.UnionType):
        return st.one_of(*(strategy_for(i) for i in t.types))
    if isinstance(t, mi.StructType):
        return struct_strategy(t.cls)
    if isinstance(t, mi.AnyType):
        return st.integers()
    raise NotImplementedError(f"no strategy for {t!r}")


def struct_strategy(cls: type[msgspec.Struct]) -> st.SearchStrategy[Any]:
    info = mi.type_info(cls)
    assert isinstance(info, mi.StructType)
    fields = {f.name: strategy_for(f.type) for f in info.fields}
    return st.fixed_dictionaries(fields).map(lambda kw: cls(**kw))


def same(a: Any, b: Any) -> bool:
    """Equality that treats NaN as equal to NaN (floats round-trip bit-exactly)."""
    if isinstance(a, float) and isinstance(b, float):
        return (math.isnan(a) and math.isnan(b)) or a == b
    return bool(a == b)
