"""Simulation truth never reaches the product, by Zenoh key or by a process it starts.

The product is what ships to a robot: ``common/`` and ``services/``, but not the
simulator (``services/sim/``) nor the device simulators (``services/<name>/sim/``).
The application (``phenorover/``) and its evaluation (``phenorover/eval/``) sit
above it and may read truth. test_imports.py checks the imports; here:

- no product module names a truth key (those under ``sim/truth/`` in
  :mod:`common.keys`): neither its name (``keys.SIM_TRUTH``) nor its key string. The
  simulated devices' keys (``sim/device/*``) are not truth in this sense: they are the
  wires the ``sim`` backends take for hardware, as a real backend takes a serial port.
- every module a product module runs as a program (``python -m <module>``) is itself
  product. A process started by function (``multiprocessing``) runs code the module
  imports, which test_imports.py already holds to the product.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from common import keys
from tests.conftest import REPO

# the product: these trees but the simulators in them
PRODUCT_TREES = ("common", "services")
SIMULATORS = ("services/sim/**/*.py", "services/*/sim/**/*.py")
# product modules that may name a truth key, and why (may only shrink)
NAMES_TRUTH = {
    "common/keys.py": "the one table of keys declares it",
    "common/acl.py": "grants it to no machine (SIMULATION_ONLY)",
}

TRUTH_PREFIX = f"{keys.PREFIX}/sim/truth/"
TRUTH_NAMES = {
    name
    for name, value in vars(keys).items()
    if isinstance(value, keys.Topic | keys.Rpc) and value.key.startswith(TRUTH_PREFIX)
}
# what a key string of truth has in it however it is spelled (a literal, an f-string)
TRUTH_TEXT = TRUTH_PREFIX.removeprefix(keys.PREFIX + "/").rstrip("/")


def product_files() -> list[Path]:
    sims = {p for pattern in SIMULATORS for p in REPO.glob(pattern)}
    return sorted(p for t in PRODUCT_TREES for p in (REPO / t).rglob("*.py") if p not in sims)


def docstrings(tree: ast.AST) -> set[int]:
    """The ids of the docstring nodes: prose may say which key truth is on."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                found.add(id(body[0].value))
    return found


def truth_references(source: str) -> list[str]:
    """Where ``source`` names a truth key: ``line: what``."""
    tree = ast.parse(source)
    prose = docstrings(tree)
    out = []
    for node in ast.walk(tree):
        line = getattr(node, "lineno", 0)
        if isinstance(node, ast.Attribute) and node.attr in TRUTH_NAMES:
            out.append(f"{line}: .{node.attr}")
        elif isinstance(node, ast.Name) and node.id in TRUTH_NAMES:
            out.append(f"{line}: {node.id}")
        elif isinstance(node, ast.ImportFrom):
            out += [f"{line}: imports {a.name}" for a in node.names if a.name in TRUTH_NAMES]
        elif (
            isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and TRUTH_TEXT in node.value
            and id(node) not in prose
        ):
            out.append(f"{line}: {node.value!r}")
    return out


def module_file(name: str) -> Path | None:
    """The file of repository module ``name`` (a package: its ``__init__.py``), else None."""
    base = REPO.joinpath(*name.split("."))
    for p in (base.with_suffix(".py"), base / "__init__.py"):
        if p.is_file():
            return p
    return None


def spawned(source: str) -> set[str]:
    """The repository modules ``source`` may run as programs: in a module that starts
    ``python -m`` (has the string ``"-m"``), every string naming a repository module,
    whether in the command itself or in a constant or default it is built from."""
    consts = [
        n.value
        for n in ast.walk(ast.parse(source))
        if isinstance(n, ast.Constant) and isinstance(n.value, str)
    ]
    if "-m" not in consts:
        return set()
    return {c for c in consts if c.split(".")[0] in ("common", "services", "phenorover")}


def is_product(module: str) -> bool:
    path = module_file(module)
    return path is not None and path in set(product_files())


def test_the_truth_keys_are_found() -> None:
    assert "SIM_TRUTH" in TRUTH_NAMES, TRUTH_NAMES
    assert TRUTH_TEXT == "sim/truth"


def test_no_product_module_names_a_truth_key() -> None:
    found = [
        f"{p.relative_to(REPO)}:{ref}"
        for p in product_files()
        if p.relative_to(REPO).as_posix() not in NAMES_TRUTH
        for ref in truth_references(p.read_text())
    ]
    assert not found, "\n".join(found)


def test_each_module_allowed_to_name_truth_still_does() -> None:
    idle = [f for f in NAMES_TRUTH if not truth_references((REPO / f).read_text())]
    assert not idle, f"take these out of NAMES_TRUTH: {idle}"


def test_every_module_a_product_module_runs_is_product() -> None:
    runs = {
        (p.relative_to(REPO).as_posix(), m) for p in product_files() for m in spawned(p.read_text())
    }
    bad = [f"{where} runs {m}" for where, m in sorted(runs) if not is_product(m)]
    assert not bad, "\n".join(bad)
    # the check sees what there is: the mission runs registration and the traits
    assert {m for _, m in runs} >= {"services.register", "services.traits"}, runs


@pytest.mark.parametrize(
    ("source", "refs"),
    [
        ("from common import keys\nbus.subscribe(keys.SIM_TRUTH, f)", 1),
        ("from common.keys import SIM_TRUTH\nbus.subscribe(SIM_TRUTH.within(ns), f)", 2),
        ('session.declare_subscriber("phenorover/sim/truth/pose", f)', 1),
        ('key = f"{PREFIX}/rover1/sim/truth/**"', 1),
        ('"""The dashboard; truth (``sim/truth/pose``) is the evaluation\'s."""', 0),
        ("bus.subscribe(keys.SIM_ANTENNAS, f)", 0),
    ],
)
def test_the_truth_check_itself(source: str, refs: int) -> None:
    """Attribute, name, import and key string are seen; docstrings and the simulated
    devices' wires are not truth."""
    assert len(truth_references(source)) == refs


@pytest.mark.parametrize(
    ("source", "product"),
    [
        ('M = "services.traits"\ncmd = [sys.executable, "-m", M]', True),
        ('def job(m: str = "services.register"):\n    run(["python", "-m", m])', True),
        ('cmd = [sys.executable, "-m", "phenorover.eval.truth_view"]', False),
        ('cmd = [sys.executable, "-m", "services.sim"]', False),
        ('cmd = [sys.executable, "-m", "services.gnss.sim.reach"]', False),
    ],
)
def test_the_spawn_check_itself(source: str, product: bool) -> None:
    (module,) = spawned(source)
    assert is_product(module) == product
