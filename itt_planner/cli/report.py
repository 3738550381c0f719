"""`itt-planner report PLAN -o report.html|png`: a static report for people without Rerun."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from itt_planner.cli._app import JSON_OPTION, app, emit, errors_to_exit


def _human(result: dict[str, Any]) -> str:
    return (f"wrote {result['output']}: {result['course']} {result['length_km']:.2f} km, "
            f"finish {result['finish_time']}, {result['average_power_w']:.0f} W average")


@app.command("report")
def report_cli(
    plan_path: Path = typer.Argument(..., help="A saved plan (.plan.npz).", exists=True,
                                     dir_okay=False),
    output: Path = typer.Option(..., "--output", "-o", help="report.html or report.png"),
    course: str | None = typer.Option(
        None, "--course", "-c",
        help="Course of the plan (GPS file, .course.npz or demo name); default: the course "
             "named in the plan's header."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Render the plan's power, speed and elevation against distance, and corner close-ups."""
    with errors_to_exit(as_json):
        result = make_report(plan_path, output, course)
        emit(result, as_json, _human)


def make_report(plan_path: Path, output: Path, course_spec: str | None) -> dict[str, Any]:
    """Load the plan and its course, write the report, return its summary.

    Raises:
        IttError: unreadable plan or course, no course given or named, unwritable output.
    """
    from itt_planner.course_loader import load_course  # noqa: PLC0415
    from itt_planner.errors import IttError  # noqa: PLC0415
    from itt_planner.plan import Plan  # noqa: PLC0415
    from itt_planner.report import rider_from_plan, summary, write_report  # noqa: PLC0415

    if plan_path.suffix.lower() == ".mcap":
        raise IttError(f"{plan_path}: reports of ride logs are not supported yet; "
                       "pass the .plan.npz")
    plan = Plan.load(plan_path)
    spec = course_spec or plan.meta.get("course")
    if not spec:
        raise IttError(f"{plan_path}: the plan names no course; pass --course")
    course = load_course(spec)
    rider = rider_from_plan(plan)
    path = write_report(plan, course, output, rider)
    return {"output": str(path), **summary(plan, course, rider)}
