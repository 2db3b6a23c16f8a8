"""The docs' reference tables are the code's (phenorover.refdocs): a generated region that
differs from what the code makes fails, and so does a config option without a meaning (its
attribute docstring), so a new option cannot land undocumented."""

from __future__ import annotations

import importlib
from pathlib import Path

import msgspec
import pytest
from msgspec import inspect as mi

from phenorover import refdocs
from phenorover.refdocs_tables import field_docs, schema_rows, struct_table
from services import JOBS, SERVICES

ROOTS = (
    "common.config:Manifest",
    "common.field_model:FieldLayout",
    "common.field_geosettings:GeoSettings",
    "common.robot:Robot",
    *SERVICES.values(),
    *JOBS.values(),
)


def _load(spec: str) -> type:
    module, _, attr = spec.partition(":")
    t: type = getattr(importlib.import_module(module), attr)
    return t


def _structs(t: object) -> list[type]:
    if isinstance(t, mi.StructType):
        return [t.cls]
    inner = [getattr(t, a) for a in ("item_type", "key_type", "value_type") if hasattr(t, a)]
    inner += [*getattr(t, "types", ()), *getattr(t, "item_types", ())]
    return [c for x in inner for c in _structs(x)]


def config_structs() -> list[type]:
    """Every Struct a manifest, a field, the robot description or a service's table
    decodes into, nested ones included."""
    seen: dict[type, None] = {}
    todo = [_load(spec) for spec in ROOTS]
    while todo:
        cls = todo.pop()
        if cls in seen:
            continue
        seen[cls] = None
        info = mi.type_info(cls)
        assert isinstance(info, mi.StructType)
        todo += [c for f in info.fields for c in _structs(f.type)]
    return list(seen)


def _name(cls: type) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"


def test_generated_regions_are_the_codes() -> None:
    assert refdocs.run(check=True) == [], "docs drifted from the code: run `make docs`"


@pytest.mark.parametrize("cls", config_structs(), ids=_name)
def test_every_option_has_a_meaning(cls: type) -> None:
    missing = [name for name, doc in field_docs(cls).items() if not doc]
    assert not missing, f"{_name(cls)}: no attribute docstring under {', '.join(missing)}"


def _floats(t: mi.Type) -> list[mi.FloatType]:
    """The float types within ``t`` (through unions, lists, tuples and dicts)."""
    if isinstance(t, mi.FloatType):
        return [t]
    inner: list[mi.Type] = []
    if isinstance(t, mi.UnionType):
        inner = list(t.types)
    elif isinstance(t, mi.TupleType):
        inner = list(t.item_types)
    elif isinstance(t, mi.ListType | mi.VarTupleType | mi.SetType | mi.FrozenSetType):
        inner = [t.item_type]
    elif isinstance(t, mi.DictType):
        inner = [t.value_type]
    return [f for i in inner for f in _floats(i)]


@pytest.mark.parametrize("cls", config_structs(), ids=_name)
def test_every_number_option_refuses_inf_and_nan(cls: type) -> None:
    """A TOML ``inf`` or ``nan`` is one line naming the key, never a run gone wrong:
    every float an option holds is bounded both ways (``common.messages.core``'s
    ``Finite``, ``Positive``, ``NonNegative`` or bounds of its own)."""
    open_ended = [
        f.name
        for f in msgspec.structs.fields(cls)
        for t in _floats(mi.type_info(f.type))
        if (t.ge, t.gt) == (None, None) or (t.le, t.lt) == (None, None)
    ]
    assert not open_ended, f"{_name(cls)}: unbounded numbers in {', '.join(open_ended)}"


def test_every_mission_log_column_has_a_meaning() -> None:
    from common.missionlog import SCHEMA

    for table in ("mission", "steps", "events"):
        assert all(text for _, _, text in schema_rows(SCHEMA, table)), table


def test_a_drift_is_one_line_per_table(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A changed default in a doc's copy is reported, and rewriting restores it."""
    (tmp_path / "docs").mkdir()
    doc = tmp_path / "docs" / "t.md"
    begin = refdocs.BEGIN + "services.planner.budget.PlanBudget -->\n"
    doc.write_text(f"intro\n{begin}\n| stale |\n\n{refdocs.END}\nafter\n")
    assert [line.split(":")[:2] for line in refdocs.run(tmp_path, check=True)] == [
        ["t.md", " services.planner.budget.PlanBudget"]
    ]
    assert refdocs.run(tmp_path) and refdocs.run(tmp_path, check=True) == []
    text = doc.read_text()
    assert text.startswith("intro\n") and text.endswith(f"{refdocs.END}\nafter\n")
    assert "| `worker_memory_mb` |" in text


def test_defaults_are_the_runtime_values() -> None:
    from services.mission.config import MissionConfig

    table = struct_table(MissionConfig, "services.mission")
    assert "| `arrival_tolerance_m` | number > 0, ≤ 100 | 0.05 |" in table
    assert "| `profile` | table | `{ scan_id = 1, resolution = 8, quality = 2 }` |" in table


def test_a_bad_marker_is_one_line(tmp_path: Path) -> None:
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "t.md").write_text(
        f"{refdocs.BEGIN}services.nope.Config -->\n{refdocs.END}\n"
    )
    with pytest.raises(refdocs.RefDocsError, match=r"^t.md: services.nope.Config: no such"):
        refdocs.run(tmp_path, check=True)


def test_a_text_default_is_a_toml_string() -> None:
    from phenorover.refdocs_tables import toml

    assert toml('a"\\b\r\n\x00\xff') == '"a\\"\\\\b\\r\\n\\u0000\\u00ff"'


def test_a_tuple_default_is_a_toml_array() -> None:
    from phenorover.refdocs_tables import toml

    assert toml(()) == "[]" and toml((0.5, 1)) == "[0.5, 1]" and toml([(1, 2)]) == "[[1, 2]]"
