"""Command line: `itt-planner SUBCOMMAND ...` (see `itt-planner --help`).

Each sub-command lives in its own module and registers on the shared Typer `app`;
heavy libraries (CasADi, Rerun, DDS) are imported inside the commands so that
`--help` stays fast.
"""

from __future__ import annotations

from itt_planner.cli._app import app

# Importing the command modules registers their commands on `app`, in `--help` order.
# isort: off
from itt_planner.cli import course, ridelog, report, simulate, node  # noqa: F401
from itt_planner.cli import plan, bags, calibrate, sweep  # noqa: F401
# isort: on

__all__ = ["app", "main"]


def main() -> None:
    """Console-script entry point."""
    app()
