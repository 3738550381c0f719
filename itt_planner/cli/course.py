"""`itt-planner course ...`: inspect and convert courses."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from itt_planner.cli._app import JSON_OPTION, app, emit, errors_to_exit

course_app = typer.Typer(name="course", help="Inspect and convert courses.", no_args_is_help=True)
app.add_typer(course_app)

_START = typer.Option(None, "--start", help="Race start on a GPS track: distance along the ride "
                      "('850m', '1.2km') or elapsed time ('4:10', '250s'). Default: detected.")
_FINISH = typer.Option(None, "--finish", help="Race finish, as --start. Default: detected "
                       "(a post-finish U-turn is cut).")
_ROUTE = typer.Option(None, "--route", help="The race's planned route (GPX/TCX/FIT/CSV): start "
                      "and finish are found on the ride, and its altitude can be used.")
_ELEVATION = typer.Option("auto", "--elevation", help="Altitude source: auto (mix with a "
                          "route, else device), device, smoothed, route, mix.")
_TOLERANCE = typer.Option(5.0, "--elevation-tolerance", help="Warn when route and device "
                          "altitude disagree by more than this (m).")
_WIDTH = typer.Option(None, "--road-width", help="Full road width of a GPS course (m); "
                      "default 6.0 (closed-road time trial). Per stretch: a GPS-course YAML.")
_LAPS = typer.Option(1, "--laps", help="Laps of a closed-loop track the race rides (a "
                     "circuit time trial; `laps:` in a GPS-course YAML for plan and replay).")


def _options(start: str | None, finish: str | None, route: Path | None, elevation: str,
             tolerance: float, width: float | None, laps: int = 1) -> Any:
    """`CourseOptions` from the CLI flags, or None when all are at their defaults."""
    from itt_planner.course.elevation import ElevationOptions  # noqa: PLC0415
    from itt_planner.course.fit import CourseOptions  # noqa: PLC0415
    from itt_planner.course.geometry import GPS_ROAD_WIDTH_M  # noqa: PLC0415
    from itt_planner.course.track_files import read_recording  # noqa: PLC0415
    from itt_planner.course.trim import TrimOptions, parse_mark  # noqa: PLC0415

    if (start, finish, route, elevation, tolerance, width, laps) == (
            None, None, None, "auto", 5.0, None, 1):
        return None
    return CourseOptions(
        trim=TrimOptions(start=parse_mark(start), finish=parse_mark(finish),
                         route=read_recording(route) if route else None),
        elevation=ElevationOptions(source=elevation, tolerance_m=tolerance),
        road_width_m=GPS_ROAD_WIDTH_M if width is None else width, laps=laps)


def _human_info(info: dict[str, Any]) -> str:
    lines = [
        f"{info['name']}: {info['length_m'] / 1000:.2f} km, +{info['gain_m']:.0f} m / "
        f"-{info['loss_m']:.0f} m, grades {info['min_grade'] * 100:.1f} % to "
        f"{info['max_grade'] * 100:.1f} %, "
        f"{'closed loop' if info['closed_loop'] else 'point to point'}"
        + (f", {laps['laps']} laps of {laps['lap_m'] / 1000:.2f} km"
           if (laps := (info.get("build") or {}).get("laps")) else "")
        + (" (SYNTHETIC)" if info["synthetic"] else ""),
        (f"{info['n_corners']} corners, tightest radius {info['min_radius_m']} m; road width "
         f"{info['road_width_m'][0]:g}-{info['road_width_m'][1]:g} m"),
    ]
    build = info.get("build") or {}
    if "trim" in build:
        t = build["trim"]
        lines.append(f"race: {t['start_m']:.0f} m to {t['finish_m']:.0f} m of a "
                     f"{t['ride_length_m']:.0f} m ride (start {t['start_method']}, finish "
                     f"{t['finish_method']})")
        lines += [f"  {note}" for note in t["notes"]]
    if "elevation" in build:
        e = build["elevation"]
        lines.append(f"altitude: {e['source']} (asked: {e['requested']}); " + ", ".join(
            f"{k} {v['min_grade'] * 100:.1f}..{v['max_grade'] * 100:.1f} %"
            for k, v in e["profiles"].items()))
    if build.get("air_temperature_c") is not None:
        lines.append(f"air: {build['air_temperature_c']:.1f} C recorded (the median of the "
                     "ride's records): plan and replay --air-temperature-c plan in it")
    lines += [f"WARNING: {w}" for w in info.get("warnings", [])]
    lines += [
        f"  {c['apex_s_m'] / 1000:7.3f} km  {c['direction']:5s} {c['angle_deg']:6.1f} deg  "
        f"R {c['min_radius_m']:6.1f} m" for c in info["corners"]
    ]
    return "\n".join(lines)


@course_app.command("info")
def info_cli(
    course: str = typer.Argument(..., help="GPS track (GPX/TCX/FIT/CSV), saved course, course "
                                 "YAML, or demo name."),
    start: str | None = _START, finish: str | None = _FINISH, route: Path | None = _ROUTE,
    elevation: str = _ELEVATION, tolerance: float = _TOLERANCE, width: float | None = _WIDTH,
    laps: int = _LAPS, as_json: bool = JSON_OPTION,
) -> None:
    """Print length, climbing, grades, trimming, altitude checks, width and the corners."""
    from itt_planner.course.loader import load_course  # noqa: PLC0415

    with errors_to_exit(as_json):
        options = _options(start, finish, route, elevation, tolerance, width, laps)
        emit(load_course(course, options).summary(), as_json, _human_info)


@course_app.command("save")
def save_cli(
    course: str = typer.Argument(..., help="GPS track, saved course, course YAML, or demo name."),
    output: Path = typer.Option(..., "--output", "-o", help="Where to write the .course.npz."),
    start: str | None = _START, finish: str | None = _FINISH, route: Path | None = _ROUTE,
    elevation: str = _ELEVATION, tolerance: float = _TOLERANCE, width: float | None = _WIDTH,
    laps: int = _LAPS, as_json: bool = JSON_OPTION,
) -> None:
    """Build a course and save it in the project's own format (with how it was built)."""
    from itt_planner.course.loader import load_course  # noqa: PLC0415

    with errors_to_exit(as_json):
        options = _options(start, finish, route, elevation, tolerance, width, laps)
        built = load_course(course, options)
        path = built.save(output)
        emit({"output": str(path), "length_m": round(built.length_m, 1),
              "n_corners": len(built.corners), "warnings": built.summary()["warnings"]},
             as_json,
             lambda r: f"wrote {r['output']} ({r['length_m'] / 1000:.2f} km, "
                       f"{r['n_corners']} corners)"
                       + "".join(f"\nWARNING: {w}" for w in r["warnings"]))
