"""The Typer application and the helpers every sub-command shares.

Sub-command modules register on `app`; they parse arguments, call one plain library
function, and hand its result to `emit`. Library errors (`IttError`) become
`ERROR: ...` on stderr (or `{"error": ...}` with `--json`) and exit code 1 here, and
only here.
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import typer

from itt_planner.errors import IttError

app = typer.Typer(
    name="itt-planner",
    help="Pacing and cornering for cycling time trials: courses, plans, replays, ROS 2 node.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)

JSON_OPTION = typer.Option(False, "--json", help="Print exactly one JSON object on stdout.")


@contextmanager
def errors_to_exit(as_json: bool) -> Iterator[None]:
    """Turn library errors into a one-line message and exit code 1 (no traceback)."""
    try:
        yield
    except IttError as err:
        if as_json:
            typer.echo(json.dumps({"error": str(err), "type": type(err).__name__}))
        typer.echo(f"ERROR: {err}", err=True)
        raise typer.Exit(code=1) from None


def emit(result: dict[str, Any], as_json: bool, human: Callable[[dict[str, Any]], str]) -> None:
    """Print `result` as one JSON object, or as the text `human(result)`."""
    if as_json:
        typer.echo(json.dumps(_plain(result), default=str, allow_nan=False))
    else:
        typer.echo(human(result))


def _plain(value: Any) -> Any:
    """JSON-ready: arrays as lists, NaN and infinities as null (JSON has neither: Python
    wrote `NaN`, which `jq` and other readers refuse; a simulated ride that did not
    finish has no finish time)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if hasattr(value, "tolist"):
        return _plain(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def progress_enabled() -> bool:
    """Progress bars go to stderr, and only when someone is watching it."""
    return sys.stderr.isatty()
