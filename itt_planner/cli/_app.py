"""The Typer application and the helpers every sub-command shares.

Sub-command modules register on `app`; they parse arguments, call one plain library
function, and hand its result to `emit`. Library errors (`IttError`) become
`ERROR: ...` on stderr (or `{"error": ...}` with `--json`) and exit code 1 here, and
only here.
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

import typer

from itt_planner.errors import IttError

if TYPE_CHECKING:
    from itt_planner.model.conditions import Conditions

app = typer.Typer(
    name="itt-planner",
    help="Pacing and cornering for cycling time trials: courses, plans, replays, ROS 2 node.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)

JSON_OPTION = typer.Option(False, "--json", help="Print exactly one JSON object on stdout.")

#: The day's grip, wind and air, as `plan` and `replay` take them (`day_conditions`).
MU_OPTION = typer.Option(1.0, "--mu", help="Tyre-road grip (1.0 dry, ~0.6 wet).")
WIND_KMH_OPTION = typer.Option(0.0, "--wind-kmh", help="Wind speed (km/h).")
WIND_FROM_DEG_OPTION = typer.Option(0.0, "--wind-from-deg",
                                    help="Direction the wind blows FROM (deg, 0 = North).")
AIR_DENSITY_OPTION = typer.Option(
    None, "--air-density-kgpm3",
    help="Air density (kg/m^3); default the paper's 1.23 at any altitude (a warning "
         "gives the course's own when it differs by over 3 %).")
AIR_TEMPERATURE_OPTION = typer.Option(
    None, "--air-temperature-c",
    help="The day's air temperature (C): plans in the course's own air, ISA pressure at "
         "its mean altitude at this temperature (instead of --air-density-kgpm3).")


def day_conditions(mu: float, wind_kmh: float, wind_from_deg: float,
                   air_density_kgpm3: float | None, air_temperature_c: float | None = None,
                   mean_altitude_m: float = 0.0) -> Conditions:
    """The conditions of the options above, in SI units (`Conditions.from_meteo`): the
    air at `air_temperature_c` on a course at `mean_altitude_m`, else of density
    `air_density_kgpm3`, else the paper's.

    Raises:
        RiderError: a value out of range (names the field).
        IttError: both an air density and a temperature.
    """
    from itt_planner.model.conditions import Conditions, day_air_density_kgpm3  # noqa: PLC0415

    conditions = Conditions.from_meteo(wind_kmh=wind_kmh, wind_from_deg=wind_from_deg, mu=mu)
    check_day_air(air_density_kgpm3, air_temperature_c)
    if air_temperature_c is not None:
        air_density_kgpm3 = day_air_density_kgpm3(mean_altitude_m, air_temperature_c)
    if air_density_kgpm3 is None:
        return conditions
    return dataclasses.replace(conditions, air_density_kgpm3=air_density_kgpm3)


def check_day_air(air_density_kgpm3: float | None, air_temperature_c: float | None) -> None:
    """Refuse both `--air-density-kgpm3` and `--air-temperature-c`.

    Raises:
        IttError: both given.
    """
    if air_density_kgpm3 is not None and air_temperature_c is not None:
        raise IttError("--air-density-kgpm3 and --air-temperature-c: give one (the "
                       "temperature sets the density at the course's altitude)")


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
