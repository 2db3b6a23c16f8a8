"""``phenorover eval``: scoring a simulated run against the simulator's truth."""

from __future__ import annotations

import argparse

from phenorover.eval import traits_cli as eval_traits
from phenorover.eval.register import cli as eval_register


def add_command(p: argparse.ArgumentParser) -> None:
    """``phenorover eval WHAT``."""
    evals = p.add_subparsers(dest="what", required=True)
    e = evals.add_parser("register", help="score a registration against the true poses")
    eval_register.add_arguments(e)
    e.set_defaults(func=eval_register.run)
    t = evals.add_parser("traits", help="score a survey's traits against the simulated plants")
    eval_traits.add_arguments(t)
    t.set_defaults(func=eval_traits.run)
