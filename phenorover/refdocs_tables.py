"""The reference tables of the docs, made from the code: a config Struct's options (their
meanings are the attribute docstrings under its fields, read with :mod:`ast`; defaults and
bounds are the runtime ones) and a table of the mission log's SQL schema (the meanings are
the ``-- comments`` after its columns). :mod:`phenorover.refdocs` puts them into the docs."""

from __future__ import annotations

import ast
import functools
import inspect
import math
import re
import sys
from typing import Any

import msgspec
from msgspec import inspect as mi

# a bound this large is the "finite" of common.messages.core, not a limit worth a reader's time
_HUGE = 1e12
_INLINE_MAX = 60
_ROLE = re.compile(r":[a-z]+:`~?([^`]+)`")


def markdown(text: str) -> str:
    """Docstring text (reStructuredText roles and literals) as one markdown table cell."""
    text = _ROLE.sub(r"`\1`", text).replace("``", "`")
    return " ".join(text.split()).replace("|", "\\|")


@functools.cache
def _module_docstrings(module: str) -> dict[tuple[str, str], str]:
    """(class name, field) -> the string literal on the line(s) after the field."""
    tree = ast.parse(inspect.getsource(sys.modules[module]))
    out: dict[tuple[str, str], str] = {}
    for node in ast.walk(tree):
        if not isinstance(node, ast.ClassDef):
            continue
        for stmt, after in zip(node.body, [*node.body[1:], None], strict=True):
            if (
                isinstance(stmt, ast.AnnAssign)
                and isinstance(stmt.target, ast.Name)
                and isinstance(after, ast.Expr)
                and isinstance(after.value, ast.Constant)
                and isinstance(after.value.value, str)
            ):
                out[node.name, stmt.target.id] = inspect.cleandoc(after.value.value)
    return out


def field_docs(cls: type) -> dict[str, str]:
    """Each field of ``cls`` (a msgspec Struct) -> its attribute docstring ("" if none),
    found in the class that declares the field (``cls`` or a base)."""
    found: dict[str, str] = {}
    for base in reversed(cls.__mro__):
        if issubclass(base, msgspec.Struct) and base is not msgspec.Struct:
            docs = _module_docstrings(base.__module__)
            found |= {name: doc for (c, name), doc in docs.items() if c == base.__name__}
    return {f.name: found.get(f.name, "") for f in msgspec.structs.fields(cls)}


def number(v: float) -> str:
    """``60``, ``0.05``, ``2e9``: a whole number as an integer, a large round one with an
    exponent."""
    if not math.isfinite(v):
        return "inf" if v > 0 else "-inf" if v < 0 else "nan"
    if v == int(v) and abs(v) < 1e6:
        return str(int(v))
    short = f"{v:.3g}"
    if v == int(v) and float(short) == v:
        mant, _, exp = short.partition("e+")
        return f"{mant}e{int(exp)}" if exp else mant
    return repr(v)


_ESCAPES = {"\\": "\\\\", '"': '\\"', "\n": "\\n", "\r": "\\r", "\t": "\\t"}


def _escape(c: str) -> str:
    """A character of a TOML basic string: printable ASCII as itself, else escaped."""
    return c if " " <= c <= "~" else f"\\u{ord(c):04x}"


def toml(v: Any) -> str:
    """A plain value (msgspec builtins) written the TOML way, on one line."""
    if v is None:
        return "none"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        return number(v)
    if isinstance(v, str):
        return '"' + "".join(_ESCAPES.get(c) or _escape(c) for c in v) + '"'
    if isinstance(v, list | tuple):  # a TOML array either way
        return "[" + ", ".join(toml(x) for x in v) + "]"
    if isinstance(v, dict):
        items = [f"{k} = {toml(x)}" for k, x in v.items() if x is not None]
        return "{ " + ", ".join(items) + " }" if items else "{}"
    return str(v)


def default_cell(f: mi.Field) -> str:
    if f.required:
        return "required"
    value = f.default_factory() if f.default is msgspec.NODEFAULT else f.default
    if value is None or isinstance(value, bool | int | float):
        return toml(value)
    text = toml(msgspec.to_builtins(value))
    return f"`{text}`" if len(text) <= _INLINE_MAX else "per key"


def _bound(*pairs: tuple[str, float | None]) -> tuple[str, float] | None:
    """The first bound given, unless it is one only to keep a number finite."""
    op, v = next(((op, v) for op, v in pairs if v is not None), ("", None))
    return None if v is None or not abs(v) < _HUGE else (op, v)


def _bounds(t: mi.FloatType | mi.IntType) -> str:
    lo = _bound((">", t.gt), ("≥", t.ge))
    hi = _bound(("<", t.lt), ("≤", t.le))
    if lo and hi and lo[0] == "≥" and hi[0] == "≤":
        return f" {number(lo[1])} to {number(hi[1])}"
    return ",".join(f" {op} {number(v)}" for op, v in filter(None, (lo, hi)))


def type_cell(t: Any) -> str:
    """A msgspec type compactly: its kind and bounds, a choice of literals."""
    if isinstance(t, mi.FloatType):
        return "number" + _bounds(t)
    if isinstance(t, mi.IntType):
        return "integer" + _bounds(t)
    if isinstance(t, mi.LiteralType):
        return "one of " + ", ".join(f"`{v}`" for v in t.values)
    if isinstance(t, mi.UnionType):
        kinds = list(dict.fromkeys(type_cell(x) for x in t.types if not isinstance(x, mi.NoneType)))
        return " or ".join(kinds) + (" or none" if t.includes_none else "")
    if isinstance(t, mi.ListType | mi.VarTupleType | mi.SetType | mi.FrozenSetType):
        return "list of " + type_cell(t.item_type)
    if isinstance(t, mi.TupleType):
        return "[" + ", ".join(type_cell(x) for x in t.item_types) + "]"
    if isinstance(t, mi.DictType):
        inner = "any" if isinstance(t.value_type, mi.DictType) else type_cell(t.value_type)
        return "table" + ("" if inner == "any" else f" of {inner}")
    simple = {mi.BoolType: "bool", mi.StrType: "text", mi.StructType: "table"}
    simple |= {mi.DateType: "date", mi.AnyType: "any"}
    return next((name for kind, name in simple.items() if isinstance(t, kind)), "value")


def _nested(t: Any) -> str | None:
    """``[x]`` or ``[[x]]`` when the field holds a table or a list of tables."""
    if isinstance(t, mi.UnionType):
        found = [_nested(x) for x in t.types if not isinstance(x, mi.NoneType)]
        return found[0] if len(found) == 1 else None
    if isinstance(t, mi.StructType):
        return "[{}]"
    if isinstance(t, mi.ListType) and isinstance(t.item_type, mi.StructType):
        return "[[{}]]"
    return None


def struct_table(cls: type, section: str = "") -> str:
    """The markdown table of a config Struct's options: key, type, default, meaning.
    With ``section`` (``services.nav``) a field holding a table too large to write
    inline is keyed by its table's name (``[services.nav.ekf]``)."""
    info = mi.type_info(cls)
    assert isinstance(info, mi.StructType), cls
    docs = field_docs(cls)
    rows = ["| key | type | default | meaning |", "|---|---|---|---|"]
    for f in info.fields:
        shape, default = _nested(f.type), default_cell(f)
        key = f"`{f.encode_name}`"
        if section and shape and not default.startswith("`"):
            key = "`" + shape.format(f"{section}.{f.encode_name}") + "`"
        cells = (key, type_cell(f.type), default, markdown(docs[f.name]))
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


_TABLE = re.compile(r"CREATE TABLE IF NOT EXISTS (\w+) \((.*?)\n\);", re.S)


def schema_rows(schema: str, table: str) -> list[tuple[list[str], str, str]]:
    """(columns, their SQL type and constraints, meaning) per line of ``table``'s
    definition in ``schema``: the columns of one line share the ``--`` comment after
    them, continued on the comment-only lines below."""
    body = next(m.group(2) for m in _TABLE.finditer(schema) if m.group(1) == table)
    rows: list[tuple[list[str], str, str]] = []
    for line in body.strip().splitlines():
        code, _, comment = line.partition("--")
        if not code.strip():
            names, typ, text = rows[-1]
            rows[-1] = (names, typ, f"{text} {comment.strip()}")
            continue
        defs = [d.split() for d in code.split(",") if d.strip()]
        types = {" ".join(d[1:]) for d in defs}
        typ = types.pop() if len(types) == 1 else ", ".join(sorted(types))
        rows.append(([d[0] for d in defs], typ, comment.strip()))
    return rows


def _sql_type(typ: str) -> str:
    kind, _, rest = typ.partition(" ")
    rest = rest.lower().replace(" default", ", default")
    return ", ".join([kind, *filter(None, [rest])])


def schema_table(schema: str, table: str, added: tuple[tuple[str, str], ...] = ()) -> str:
    """The markdown table of one SQL table's columns; a column in ``added`` (added to
    an older log by ALTER TABLE) says so."""
    late = {name for name, _ in added}
    rows = ["| column | type | meaning |", "|---|---|---|"]
    for names, typ, text in schema_rows(schema, table):
        if late.issuperset(names):
            text += "; added to an older log when a mission resumes it"
        cols = ", ".join(f"`{n}`" for n in names)
        rows.append(f"| {cols} | {_sql_type(typ)} | {markdown(text)} |")
    return "\n".join(rows)
