"""The ``phenorover`` command imports only the command it runs: the everyday ones answer
without loading OR-Tools, numba or matplotlib, and every other command still parses."""

from __future__ import annotations

import subprocess
import sys

import pytest

from phenorover.cli import LAZY, main
from tests.conftest import REPO

HEAVY = ("ortools", "numba", "matplotlib", "scipy")


@pytest.mark.parametrize(
    "argv", [["--help"], ["status", "--help"], ["certs", "--help"], ["up", "--help"]]
)
def test_everyday_commands_load_nothing_heavy(argv: list[str]) -> None:
    code = (
        "import sys\nfrom phenorover.cli import main\ntry:\n"
        f"    main({argv!r})\nexcept SystemExit:\n    pass\n"
        f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))"
    )
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=60
    )
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1] == "[]", r.stdout[-500:]


@pytest.mark.parametrize("name", sorted(LAZY))
def test_every_lazily_loaded_command_parses(name: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        main([name, "--help"])
    assert exit_.value.code == 0
    assert f"usage: phenorover {name}" in capsys.readouterr().out


def test_top_level_options_before_the_command_are_understood(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["--log-level", "debug", "plan", "--help"])
    assert exit_.value.code == 0
    assert "usage: phenorover plan" in capsys.readouterr().out
