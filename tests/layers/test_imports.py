"""The layers, checked on every import statement (lazy ones inside functions too):
``common`` imports nothing above it, a service imports ``common`` and never another
service, and neither reaches the application (``phenorover``, its evaluation
``phenorover.eval`` included: simulation truth is read there and nowhere else)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from tests.conftest import REPO

ABOVE = ("phenorover",)


def imports(path: Path) -> list[tuple[int, str]]:
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            found.append((node.lineno, node.module))
    return found


def forbidden(path: Path) -> list[str]:
    """What ``path`` may not import, by the layer it is in."""
    rel = path.relative_to(REPO).parts
    if rel[0] == "common":
        return ["services", *ABOVE]
    if rel[0] == "services" and len(rel) > 2:
        own = rel[1]
        others = [f"services.{p.name}" for p in (REPO / "services").iterdir() if p.is_dir()]
        return [o for o in others if o != f"services.{own}"] + list(ABOVE)
    return []


def violations(path: Path) -> list[str]:
    bad = forbidden(path)
    return [
        f"{path.relative_to(REPO)}:{line}: imports {mod}"
        for line, mod in imports(path)
        if any(mod == b or mod.startswith(b + ".") for b in bad)
    ]


PRODUCT = sorted(
    p for top in ("common", "services", "phenorover") for p in (REPO / top).rglob("*.py")
)


def test_no_layer_imports_above_itself_or_across_services() -> None:
    found = [v for p in PRODUCT for v in violations(p)]
    assert not found, "\n".join(found)


@pytest.mark.parametrize(
    ("where", "source", "bad"),
    [
        ("common/x.py", "from services.nav import ekf", True),
        ("common/x.py", "def f():\n    import services.sim.world", True),
        ("services/nav/x.py", "from services.sim.truth_file import read_truth", True),
        ("services/nav/x.py", "from services.nav.ekf import Ekf", False),
        ("services/viz/x.py", "import phenorover.eval.results", True),
        ("services/sim/x.py", "from phenorover.launcher import Launcher", True),
        ("phenorover/eval/x.py", "from services.sim.truth_file import TRUTH", False),
    ],
)
def test_the_check_itself(tmp_path: Path, where: str, source: str, bad: bool) -> None:
    """The walk sees module-level and lazy imports, and tells a service's own modules
    from another's (so the test above cannot pass by seeing nothing)."""
    path = REPO / where
    path_in_tmp = tmp_path / "x.py"
    path_in_tmp.write_text(source)
    bad_imports = [
        mod
        for _, mod in imports(path_in_tmp)
        if any(mod == b or mod.startswith(b + ".") for b in forbidden(path))
    ]
    assert bool(bad_imports) == bad
