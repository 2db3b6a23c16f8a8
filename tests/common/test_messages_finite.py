"""Every float on the bus is finite by schema: for every message type (topics, RPC
requests and replies) and every float inside it, nested Structs (the field layout and
scanner model a plan carries too), tuples, lists, dicts and optionals included, NaN
and +-inf on the wire fail decoding with the field's path named, and the widest
finite value the field allows round-trips."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import msgspec
import msgspec.inspect as mi
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from common import keys
from common.codec import decode
from common.messages.core import FINITE_MAX, Finite


@dataclasses.dataclass(frozen=True)
class DictKey:
    """A dict key in a path (msgspec names its place ``[...]`` in errors)."""

    key: Any


Path = tuple[str | int | DictKey, ...]


def _key_example(t: mi.Type) -> Any:
    k = example(t)
    return "k" if k is None or k == "" else k


NON_FINITE = (math.nan, math.inf, -math.inf)


def _members(t: Any) -> list[type]:
    info = mi.type_info(t)
    if not isinstance(info, mi.UnionType):
        return [t]
    return [u.cls for u in info.types if isinstance(u, mi.StructType)]


WIRE_TYPES = sorted(
    {
        *keys.TOPICS.values(),
        *(r for _, r in keys.RPCS.values()),
        *(m for q, _ in keys.RPCS.values() for m in _members(q)),
    },
    key=lambda t: t.__name__,
)


def _float_ok(t: mi.FloatType, v: float) -> bool:
    return (
        (t.ge is None or v >= t.ge)
        and (t.gt is None or v > t.gt)
        and (t.le is None or v <= t.le)
        and (t.lt is None or v < t.lt)
    )


def _widest(t: mi.FloatType) -> float:
    """The largest magnitude the field accepts (its bound, or 1e300 if unbounded)."""
    hi = t.le if t.le is not None else (t.lt if t.lt is not None else FINITE_MAX)
    return float(hi) if _float_ok(t, float(hi)) else float(hi) / 2


def example(t: mi.Type) -> Any:
    """A valid value of ``t`` as msgpack builtins, every container non-empty (so every
    float in it has a place to be corrupted)."""
    if isinstance(t, mi.BoolType):
        return False
    if isinstance(t, mi.IntType):
        lo = t.ge if t.ge is not None else (t.gt + 1 if t.gt is not None else 0)
        return max(lo, 0) if t.le is None or max(lo, 0) <= t.le else lo
    if isinstance(t, mi.FloatType):
        return next(v for v in (0.0, 1.0, 0.5, -1.0) if _float_ok(t, v))
    if isinstance(t, mi.StrType):
        return "x" * (t.min_length or 0)
    if isinstance(t, mi.BytesType):
        return b""
    if isinstance(t, mi.DateType):
        return "2026-05-01"
    if isinstance(t, mi.NoneType):
        return None
    if isinstance(t, mi.EnumType):
        return next(iter(t.cls)).value
    if isinstance(t, mi.LiteralType):
        return t.values[0]
    if isinstance(t, (mi.ListType, mi.VarTupleType)):
        return [example(t.item_type)]
    if isinstance(t, mi.TupleType):
        return [example(i) for i in t.item_types]
    if isinstance(t, mi.DictType):
        return {_key_example(t.key_type): example(t.value_type)}
    if isinstance(t, mi.UnionType):
        return example(next(u for u in t.types if not isinstance(u, mi.NoneType)))
    if isinstance(t, mi.StructType):
        out = {f.encode_name: example(f.type) for f in t.fields}
        if t.tag_field is not None:
            out[t.tag_field] = t.tag
        return out
    raise NotImplementedError(f"no example for {t!r}")


def float_paths(t: mi.Type, path: Path = ()) -> list[tuple[Path, mi.FloatType]]:
    """(path into ``example(t)``, its type) of every float in ``t``."""
    if isinstance(t, mi.FloatType):
        return [(path, t)]
    if isinstance(t, (mi.ListType, mi.VarTupleType)):
        return float_paths(t.item_type, (*path, 0))
    if isinstance(t, mi.TupleType):
        return [p for i, it in enumerate(t.item_types) for p in float_paths(it, (*path, i))]
    if isinstance(t, mi.DictType):
        return float_paths(t.value_type, (*path, DictKey(_key_example(t.key_type))))
    if isinstance(t, mi.UnionType):
        inner = [u for u in t.types if not isinstance(u, mi.NoneType)]
        return float_paths(inner[0], path) if inner else []
    if isinstance(t, mi.StructType):
        return [p for f in t.fields for p in float_paths(f.type, (*path, f.encode_name))]
    return []


def with_value(obj: Any, path: Path, value: float) -> Any:
    if not path:
        return value
    head, rest = path[0], path[1:]
    if isinstance(head, DictKey):
        return {**obj, head.key: with_value(obj[head.key], rest, value)}
    if isinstance(obj, list):
        out = list(obj)
        assert isinstance(head, int)
        out[head] = with_value(obj[head], rest, value)
        return out
    return {**obj, head: with_value(obj[head], rest, value)}


def value_at(obj: Any, path: Path) -> Any:
    for p in path:
        obj = obj[p.key] if isinstance(p, DictKey) else obj[p]
    return obj


def _where(path: Path) -> str:
    return "$" + "".join(
        "[...]" if isinstance(p, DictKey) else f"[{p}]" if isinstance(p, int) else f".{p}"
        for p in path
    )


def _failures(msg_type: type) -> list[str]:
    info = mi.type_info(msg_type)
    base = example(info)
    decode(msgspec.msgpack.encode(base), msg_type)  # the example itself is valid
    bad = []
    for path, ft in float_paths(info):
        for v in NON_FINITE:
            try:
                decode(msgspec.msgpack.encode(with_value(base, path, v)), msg_type)
                bad.append(f"{_where(path)} accepted {v}")
            except msgspec.ValidationError as exc:
                # the error names the field, so the one-line log says what was wrong
                assert f"`{_where(path)}`" in str(exc), (path, str(exc))
        widest = _widest(ft)
        for v in (widest, -widest if _float_ok(ft, -widest) else widest):
            back = decode(msgspec.msgpack.encode(with_value(base, path, v)), msg_type)
            assert value_at(msgspec.to_builtins(back), path) == v, (_where(path), v)
    return bad


@pytest.mark.parametrize("msg_type", WIRE_TYPES, ids=lambda t: t.__name__)
def test_every_float_refuses_nan_and_inf_and_keeps_its_widest_finite_value(msg_type: type) -> None:
    assert _failures(msg_type) == []


def test_every_wire_type_has_been_walked() -> None:
    walked = {t.__name__ for t in WIRE_TYPES}
    assert {"NavSatFix", "Odometry", "GnssHeading", "FollowRoute", "PlanResult"} <= walked
    from common.messages.nav import FollowRoute
    from common.messages.plan import PlanResult

    assert "$.legs[0].final_yaw" in [_where(p) for p, _ in float_paths(mi.type_info(FollowRoute))]
    plan = [_where(p) for p, _ in float_paths(mi.type_info(PlanResult))]
    assert {"$.layout.origin_alt", "$.cover.bound", "$.origin[1]"} <= set(plan)


@settings(max_examples=200, deadline=None)
@given(st.floats(allow_nan=True, allow_infinity=True))
def test_finite_is_exactly_the_finite_floats(v: float) -> None:
    class M(msgspec.Struct):
        x: Finite

    data = msgspec.msgpack.encode({"x": v})
    if math.isfinite(v) and abs(v) <= FINITE_MAX:
        assert decode(data, M).x == v
    else:
        with pytest.raises(msgspec.ValidationError, match=r"\$\.x"):
            decode(data, M)
