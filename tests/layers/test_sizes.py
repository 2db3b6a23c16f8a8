"""The product's pieces stay small enough to read: no module over ``MODULE_LINES``
lines and no function over ``FUNCTION_LINES`` (ruff's C901 and PLR0915 hold their
branching and statements, pyproject.toml). ``ALLOWED`` lists the functions let past
the length, each with why; it may only shrink: an entry that no longer needs to be
there fails too, so that it is taken out."""

from __future__ import annotations

import ast
from pathlib import Path

from tests.conftest import REPO
from tests.layers.test_imports import PRODUCT

# a module a newcomer reads in one sitting; a function that fits on a screen and a half
MODULE_LINES = 300
FUNCTION_LINES = 80
ALLOWED = {
    "services/planner/exact.py:_planar_side": (
        "a compiled (numba) kernel of the exact visibility: one vertical side of a plot "
        "under planar occlusion, column by column of sample points, most of its length "
        "its thirteen array arguments"
    ),
    "services/sim/scene.py:_first_hit": (
        "a compiled (numba) kernel, the simulated scanner's inner loop: one ray against "
        "the terrain, the foliage voxels, the targets and the boxes, nearest hit kept"
    ),
}


def long_functions(path: Path, root: Path = REPO) -> dict[str, int]:
    """``file:function`` (relative to ``root``) -> lines, of the functions (methods
    too, decorators counted) over the limit."""
    rel = path.relative_to(root).as_posix()
    out = {}
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            start = min([node.lineno, *(d.lineno for d in node.decorator_list)])
            lines = (node.end_lineno or node.lineno) - start + 1
            if lines > FUNCTION_LINES:
                out[f"{rel}:{node.name}"] = lines
    return out


def test_no_product_module_is_over_the_limit() -> None:
    over = {
        p.relative_to(REPO).as_posix(): n
        for p in PRODUCT
        if (n := len(p.read_text().splitlines())) > MODULE_LINES
    }
    assert not over, f"modules over {MODULE_LINES} lines (split them by what they do): {over}"


def test_no_product_function_is_over_the_limit_but_the_allowed_kernels() -> None:
    found: dict[str, int] = {}
    for p in PRODUCT:
        found |= long_functions(p)
    over = {k: n for k, n in found.items() if k not in ALLOWED}
    assert not over, f"functions over {FUNCTION_LINES} lines: {over}"
    stale = sorted(set(ALLOWED) - set(found))
    assert not stale, f"allowed but no longer over {FUNCTION_LINES} lines: take out {stale}"


def test_the_check_finds_a_long_function(tmp_path: Path) -> None:
    body = "\n".join(f"    x{i} = {i}" for i in range(FUNCTION_LINES))
    path = tmp_path / "probe.py"
    path.write_text(f"def long() -> None:\n{body}\n\n\ndef short() -> None:\n    pass\n")
    assert long_functions(path, tmp_path) == {"probe.py:long": FUNCTION_LINES + 1}
