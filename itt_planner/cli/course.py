"""`itt-planner course ...`: inspect and convert courses."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from itt_planner.cli._app import JSON_OPTION, app, emit, errors_to_exit

course_app = typer.Typer(name="course", help="Inspect and convert courses.", no_args_is_help=True)
app.add_typer(course_app)


def _human_info(info: dict[str, Any]) -> str:
    lines = [
        f"{info['name']}: {info['length_m'] / 1000:.2f} km, +{info['gain_m']:.0f} m / "
        f"-{info['loss_m']:.0f} m, grades {info['min_grade'] * 100:.1f} % to "
        f"{info['max_grade'] * 100:.1f} %, {'closed loop' if info['closed_loop'] else 'point to point'}"
        + (" (SYNTHETIC)" if info["synthetic"] else ""),
        f"{info['n_corners']} corners, tightest radius {info['min_radius_m']} m",
    ]
    lines += [
        f"  {c['apex_s_m'] / 1000:7.3f} km  {c['direction']:5s} {c['angle_deg']:6.1f} deg  "
        f"R {c['min_radius_m']:6.1f} m" for c in info["corners"]
    ]
    return "\n".join(lines)


@course_app.command("info")
def info_cli(
    course: str = typer.Argument(..., help="GPS track (GPX/TCX/FIT/CSV), saved course, or demo name."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Print length, climbing, grades and the corner table of a course."""
    from itt_planner.course_loader import load_course  # noqa: PLC0415

    with errors_to_exit(as_json):
        emit(load_course(course).summary(), as_json, _human_info)


@course_app.command("save")
def save_cli(
    course: str = typer.Argument(..., help="GPS track, saved course, or demo name."),
    output: Path = typer.Option(..., "--output", "-o", help="Where to write the .course.npz."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Build a course and save it in the project's own format."""
    from itt_planner.course_loader import load_course  # noqa: PLC0415

    with errors_to_exit(as_json):
        built = load_course(course)
        path = built.save(output)
        emit({"output": str(path), "length_m": round(built.length_m, 1),
              "n_corners": len(built.corners)}, as_json,
             lambda r: f"wrote {r['output']} ({r['length_m'] / 1000:.2f} km, "
                       f"{r['n_corners']} corners)")


