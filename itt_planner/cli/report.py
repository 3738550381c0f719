"""`itt-planner report PLAN_OR_LOG -o report.html|png`: a static report for people without Rerun."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from itt_planner.cli._app import JSON_OPTION, app, emit, errors_to_exit


def _human(result: dict[str, Any]) -> str:
    if "plan_finish_time" in result:  # a ride
        return (f"wrote {result['output']}: {result['course']} ride, finish "
                f"{result['finish_time']} (plan {result['plan_finish_time']}), "
                f"{result['average_power_w']:.0f} W average (plan "
                f"{result['plan_average_power_w']:.0f} W), {result['fallbacks']} fallbacks "
                f"in {result['advice']} advice")
    return (f"wrote {result['output']}: {result['course']} {result['length_km']:.2f} km, "
            f"finish {result['finish_time']}, {result['average_power_w']:.0f} W average")


@app.command("report")
def report_cli(
    source: Path = typer.Argument(
        ..., help="A saved plan (.plan.npz), or a ride log written by `itt-planner replay` "
                  "(.mcap; a raw input log must be replayed first).",
        exists=True, dir_okay=False),
    output: Path = typer.Option(..., "--output", "-o", help="report.html or report.png"),
    course: str | None = typer.Option(
        None, "--course", "-c",
        help="Course (GPS file, .course.npz or demo name); default: the course named in "
             "the plan's header or the log's metadata."),
    rider: str | None = typer.Option(
        None, "--rider", help="Rider of a ride log (preset or YAML); default: the one the "
                              "log's metadata names."),
    cache_dir: Path = typer.Option(Path(".itt_cache"), "--cache-dir",
                                   help="Where full-course plans are cached (ride logs)."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Render power, speed and elevation against distance and corner close-ups; for a ride
    log, the actual ride over the plan (power, speed, W') and a summary of the advice."""
    with errors_to_exit(as_json):
        from itt_planner.view.ride_report import is_ride_log  # noqa: PLC0415

        if is_ride_log(source):
            result = make_ride_report(source, output, course, rider, cache_dir)
        else:
            result = make_report(source, output, course)
        emit(result, as_json, _human)


def make_report(plan_path: Path, output: Path, course_spec: str | None) -> dict[str, Any]:
    """Load the plan and its course, write the report, return its summary.

    Raises:
        IttError: unreadable plan or course, no course given or named, unwritable output.
    """
    from itt_planner.course.loader import load_course  # noqa: PLC0415
    from itt_planner.errors import IttError  # noqa: PLC0415
    from itt_planner.ocp.plan import Plan  # noqa: PLC0415
    from itt_planner.view.report import rider_from_plan, summary, write_report  # noqa: PLC0415

    plan = Plan.load(plan_path)
    spec = course_spec or plan.meta.get("course")
    if not spec:
        raise IttError(f"{plan_path}: the plan names no course; pass --course")
    course = load_course(spec)
    rider = rider_from_plan(plan)
    path = write_report(plan, course, output, rider)
    return {"output": str(path), **summary(plan, course, rider)}


def make_ride_report(log_path: Path, output: Path, course_spec: str | None,
                     rider_spec: str | None, cache_dir: Path) -> dict[str, Any]:
    """Load a replayed ride log and its plan, write the report, return its summary.

    Raises:
        IttError: not a replay output, unreadable log, course or rider, unwritable output.
    """
    from itt_planner.view.report import ride_summary, write_report  # noqa: PLC0415
    from itt_planner.view.ride_report import load_ride_trace, ride_setup  # noqa: PLC0415

    trace = load_ride_trace(log_path)
    course, rider, plan = ride_setup(trace, course_spec, rider_spec, cache_dir)
    path = write_report(plan, course, output, rider, ride=trace)
    return {"output": str(path), **ride_summary(trace, plan, course, rider)}
