"""`itt-planner report PLAN_OR_LOG -o report.html|png`: a static report for people without Rerun.

Beyond the plan (or the ride over the plan): a calibrated rider (`--rider me.yaml` written
by `calibrate`) is shown with each value's uncertainty and source, and when a ride with
power is known (`--ride`, or the ride file the course was fitted to) the ride is
validated against the models and the plan drawn (`itt_planner.calibration.validate`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import typer

from itt_planner.cli._app import JSON_OPTION, app, emit, errors_to_exit
from itt_planner.cli.calibrate import validation_lines

#: Models `report` replays the ride's power through by default.
VALIDATE_MODELS = ["1d", "3d"]


def _human(result: dict[str, Any]) -> str:
    if "plan_finish_time" in result:  # a ride
        ridden = ("no power meter" if result["average_power_w"] is None
                  else f"{result['average_power_w']:.0f} W average")
        head = (f"wrote {result['output']}: {result['course']} ride, finish "
                f"{result['finish_time']} (plan {result['plan_finish_time']}), {ridden} (plan "
                f"{result['plan_average_power_w']:.0f} W), {result['fallbacks']} fallbacks "
                f"in {result['advice']} advice")
    else:
        head = (f"wrote {result['output']}: {result['course']} {result['length_km']:.2f} km, "
                f"finish {result['finish_time']}, {result['average_power_w']:.0f} W average")
    return "\n".join([head, *_human_calibration(result.get("calibration")),
                      *_human_validation(result.get("validation"))])


def _human_calibration(cal: dict[str, Any] | None) -> list[str]:
    if cal is None:
        return []
    lines = [f"calibrated rider {cal['file']} (fitted on {', '.join(cal['rides'])}):"]
    lines += [f"  {k} {v['value']}" + (f"  ({v['note']})" if "note" in v else "")
              for k, v in cal["values"].items()]
    lines += [f"  refused {k}: {v}" for k, v in cal["refusals"].items()]
    lines += [f"  warning {k}: {v}" for k, v in cal.get("warnings", {}).items()]
    if cal.get("plan_rider_differs"):
        lines.append(f"  the plan was solved for other values: {cal['plan_rider_differs']}")
    return lines


def _human_validation(val: dict[str, Any] | None) -> list[str]:
    if val is None:
        return []
    if "not_run" in val:
        return [f"validation not run: {val['not_run']}"]
    lines = [(f"validation against {val['ride']} ({val['covered_m'] / 1000:.1f} km, day wind "
             f"{val['day_wind']}):"), *validation_lines(val)]
    if "three_d_vs_one_d" in val:
        lines.append(f"  3d vs 1d {val['three_d_vs_one_d']}")
    return lines


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
        None, "--rider", help="Rider (preset or YAML); default: the plan's (its header) or "
                              "the log's (its metadata). A YAML written by `calibrate` is "
                              "shown with its uncertainties and sources."),
    ride: Path | None = typer.Option(
        None, "--ride", exists=True, dir_okay=False,
        help="Ride file with power (.fit/.tcx/.gpx/.csv/.pwx, or gzipped) to validate the models "
             "and the plan against; default: the ride the course was fitted to, if any."),
    validate: bool = typer.Option(
        True, "--validate/--no-validate",
        help="Validate against the ride (--ride, or the course's own ride file)."),
    validate_model: list[str] = typer.Option(
        VALIDATE_MODELS, "--validate-model",
        help="Models replaying the ride's power (repeat; default 1d and 3d)."),
    cache_dir: Path = typer.Option(Path(".itt_cache"), "--cache-dir",
                                   help="Where full-course plans are cached (ride logs)."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Render power, speed and elevation against distance and corner close-ups; for a ride
    log, the actual ride over the plan (power, speed, W') and a summary of the advice.
    With a calibrated rider, its values, uncertainties and sources; with a ride that has
    power, the validation of the models and of the plan against it (HTML and JSON)."""
    with errors_to_exit(as_json):
        from itt_planner.view.ride_report import is_ride_log  # noqa: PLC0415

        extras = ReportExtras(rider, ride, validate, tuple(validate_model), cache_dir)
        if is_ride_log(source):
            result = make_ride_report(source, output, course, rider, cache_dir, extras)
        else:
            result = make_report(source, output, course, extras)
        emit(result, as_json, _human)


@dataclass(frozen=True)
class ReportExtras:
    """What `report` adds beyond the plan or the ride: the calibrated rider and the
    validation (module docstring); the options of the same names."""

    rider_spec: str | None
    ride: Path | None
    validate: bool
    models: tuple[str, ...]
    cache_dir: Path

    def sections(self, plan: Any, course: Any, rider: Any) -> tuple[tuple[Any, ...],
                                                                    dict[str, Any]]:
        """The report sections and their figures for the JSON (`calibration`,
        `validation`).

        Raises:
            CalibrationError: `--ride` was given and the ride cannot be validated (with the
                course's own ride file, the reason is reported instead).
        """
        from itt_planner.calibration import report_sections as rs  # noqa: PLC0415
        from itt_planner.calibration.ride_data import CalibrationError  # noqa: PLC0415
        from itt_planner.calibration.rider_file import read_calibrated_rider  # noqa: PLC0415

        sections, out = [], {}
        cal = read_calibrated_rider(self.rider_spec) if self.rider_spec else None
        if cal is not None:
            out["calibration"] = rs.calibration_summary(cal, rider, plan)
            sections.append(rs.calibration_section(out["calibration"]))
        if not self.validate:
            return tuple(sections), out
        ride = self.ride or rs.course_ride(course)
        if ride is None:
            out["validation"] = {"not_run": "no ride known: pass --ride RIDE.fit (the course "
                                            "was not fitted to a ride file)"}
        elif rider is None:
            out["validation"] = {"not_run": "the plan records no rider: pass --rider"}
        else:
            try:
                val = rs.validate_for_report(ride, course, rider, plan, self.models,
                                             self.cache_dir)
            except CalibrationError as err:
                if self.ride is not None:
                    raise
                out["validation"] = {"not_run": f"{ride} (the course's ride): {err}"}
            else:
                out["validation"] = rs.validation_summary(val)
                sections.append(rs.validation_section(val))
        return tuple(sections), out


def make_report(plan_path: Path, output: Path, course_spec: str | None,
                extras: ReportExtras | None = None) -> dict[str, Any]:
    """Load the plan and its course, write the report, return its summary.

    Raises:
        IttError: unreadable plan or course, no course given or named, unwritable output,
            an unusable `--ride` (CalibrationError).
    """
    from itt_planner.course.loader import load_course  # noqa: PLC0415
    from itt_planner.errors import IttError  # noqa: PLC0415
    from itt_planner.model.rider import load_rider  # noqa: PLC0415
    from itt_planner.ocp.plan import Plan  # noqa: PLC0415
    from itt_planner.view.report import rider_from_plan, summary, write_report  # noqa: PLC0415

    plan = Plan.load(plan_path)
    # The course as `plan -o` was given it (a file path), else its name (a demo course).
    spec = course_spec or plan.meta.get("course_spec") or plan.meta.get("course")
    if not spec:
        raise IttError(f"{plan_path}: the plan names no course; pass --course")
    course = load_course(spec)
    given = extras.rider_spec if extras is not None else None
    rider = load_rider(given) if given else rider_from_plan(plan)
    sections, figures = extras.sections(plan, course, rider) if extras else ((), {})
    path = write_report(plan, course, output, rider, sections=sections)
    return {"output": str(path), **summary(plan, course, rider), **figures}


def make_ride_report(log_path: Path, output: Path, course_spec: str | None,
                     rider_spec: str | None, cache_dir: Path,
                     extras: ReportExtras | None = None) -> dict[str, Any]:
    """Load a replayed ride log and its plan, write the report, return its summary.

    Raises:
        IttError: not a replay output, unreadable log, course or rider, unwritable output.
    """
    from itt_planner.session.config import ride_setup  # noqa: PLC0415
    from itt_planner.view.report import ride_summary, write_report  # noqa: PLC0415
    from itt_planner.view.ride_report import load_ride_trace  # noqa: PLC0415

    trace = load_ride_trace(log_path)
    course, rider, plan = ride_setup(trace, course_spec, rider_spec, cache_dir)
    if extras is not None and extras.rider_spec is None:  # the log's rider: maybe calibrated
        extras = replace(extras, rider_spec=trace.metadata.get("rider"))
    sections, figures = extras.sections(plan, course, rider) if extras else ((), {})
    path = write_report(plan, course, output, rider, ride=trace, sections=sections)
    return {"output": str(path), **ride_summary(trace, plan, course, rider), **figures}
