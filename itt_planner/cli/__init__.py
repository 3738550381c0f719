"""Command line: `itt-planner SUBCOMMAND ...` (see `itt-planner --help`).

Each sub-command lives in its own module and registers on the shared Typer `app`;
heavy libraries (CasADi, Rerun, DDS) are imported inside the commands so that
`--help` stays fast.
"""

from __future__ import annotations

from itt_planner.cli._app import app

# Importing the command modules registers their commands on `app`.
from itt_planner.cli import course as _course  # noqa: F401,E402
from itt_planner.cli import ridelog as _ridelog  # noqa: F401,E402
from itt_planner.cli import report as _report  # noqa: F401,E402
from itt_planner.cli import simulate as _simulate  # noqa: F401,E402
from itt_planner.cli import node as _node  # noqa: F401,E402
from itt_planner.cli import plan as _plan  # noqa: F401,E402
from itt_planner.cli import bags as _bags  # noqa: F401,E402
from itt_planner.cli import calibrate as _calibrate  # noqa: F401,E402
from itt_planner.cli import sweep as _sweep  # noqa: F401,E402


def main() -> None:
    """Console-script entry point."""
    app()
