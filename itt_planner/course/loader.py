"""Resolve any `--course` argument to a `Course`.

Accepted: a demo name (`verona-like`, `rovereto-like`: segment YAML shipped in
`itt_planner/data/`), a saved course (`*.course.npz`), a segment YAML file (`*.yaml`
with `segments:`), a GPS-course YAML (`*.yaml` with `track:`, below), or a GPS track
(`.gpx`, `.tcx`, `.fit`, `.csv`), which is fitted by `course_fit` with the defaults.

A GPS-course YAML carries what a track alone cannot say, so `plan`, `replay` and
`report` see the same course as `course info` (paths relative to the YAML)::

    track: race.fit             # the ride (or route) whose line is the course
    route: route.gpx            # optional: the planned route (start/finish, altitude)
    start: auto                 # or "850m", "1.2km", "4:10", "250s" (overrides)
    finish: auto
    elevation: auto             # auto | device | smoothed | route | mix
    elevation_tolerance_m: 5
    road_width_m: 6.0           # full width; default GPS_ROAD_WIDTH_M (closed road)
    widths:                     # per stretch, metres along the course (along a lap)
      - {from_m: 3200, to_m: 4100, width_m: 4.0}
    laps: 2                     # a circuit ridden twice (the track a closed loop)
"""

from __future__ import annotations

import dataclasses
from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from itt_planner.course.builder import build_course_file
from itt_planner.course.elevation import ElevationOptions
from itt_planner.course.fit import CourseOptions, WidthStretch, fit_course
from itt_planner.course.geometry import COURSE_SUFFIX, GPS_ROAD_WIDTH_M, Course
from itt_planner.course.track_files import SUFFIXES, file_sha256, read_recording, track_format
from itt_planner.course.trim import TrimOptions, parse_mark
from itt_planner.errors import CourseError

DEMO_COURSES = ("verona-like", "rovereto-like")
_GPS_KEYS = {"track", "route", "start", "finish", "elevation", "elevation_tolerance_m",
             "road_width_m", "widths", "laps", "name", "description"}


def demo_path(name: str) -> Path:
    """Path of a shipped demo course's segment YAML."""
    return Path(str(resources.files("itt_planner") / "data" / f"{name}.yaml"))


def load_course(spec: str | Path, options: CourseOptions | None = None) -> Course:
    """Build or read the course named by `spec`.

    `options` (trim, altitude source, road width) apply to a GPS track; giving them for
    anything else is an error, not silently ignored.

    Raises:
        CourseError: unknown name, missing file, unsupported suffix, options for a course
            that is not a GPS track, or a file that cannot be turned into a course (the
            message names the file and the problem).
    """
    text = str(spec)
    path = Path(text)
    is_track = bool(track_format(path))
    if options is not None and options != CourseOptions() and not is_track:
        raise CourseError(f"{text}: start/finish, route, elevation and road width options "
                          f"apply to a GPS track ({'/'.join(SUFFIXES)}), not to this course")
    if text in DEMO_COURSES and not path.exists():
        return build_course_file(demo_path(text))
    name = path.name.lower()
    if name.endswith(COURSE_SUFFIX):
        if not path.is_file():
            raise CourseError(f"{path}: no such file")
        return Course.load(path)
    if path.suffix.lower() in (".yaml", ".yml"):
        return _load_yaml(path)
    if is_track:
        return fit_course(read_recording(path), options=options or CourseOptions())
    if not path.exists():
        msg = (f"unknown course {text!r}: not a demo ({', '.join(DEMO_COURSES)}) nor a file")
        raise CourseError(msg)
    msg = (f"{path}: unsupported course file; expected {', '.join(SUFFIXES)} (or the same "
           f"gzipped), {COURSE_SUFFIX} or a segment .yaml")
    raise CourseError(msg)


def _load_yaml(path: Path) -> Course:
    if not path.is_file():
        raise CourseError(f"{path}: no such file")
    try:
        spec = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as err:
        raise CourseError(f"{path}: could not read course YAML ({err})") from None
    if not (isinstance(spec, dict) and "track" in spec):
        return build_course_file(path)
    try:
        track, options = gps_course_options(spec, path.parent)
        course = fit_course(read_recording(track), options=options)
    except CourseError as err:
        raise CourseError(f"{path}: {err}") from None
    name = str(spec.get("name", course.name))
    # The YAML is part of the course: key it to both files.
    return dataclasses.replace(course, name=name, source=f"{path} ({course.source})",
                               source_sha256=course.source_sha256 + ":" + file_sha256(path))


def gps_course_options(spec: dict[str, Any], base: Path) -> tuple[Path, CourseOptions]:
    """The track path and `CourseOptions` of a GPS-course YAML mapping.

    Raises:
        CourseError: unknown keys or invalid values (names the key).
    """
    unknown = sorted(set(spec) - _GPS_KEYS)
    if unknown:
        raise CourseError(f"unknown field(s) {', '.join(unknown)}; expected "
                          f"{', '.join(sorted(_GPS_KEYS))}")
    route = read_recording(base / str(spec["route"])) if spec.get("route") else None
    widths = spec.get("widths") or []
    if not isinstance(widths, list):
        raise CourseError("'widths' must be a list of {from_m, to_m, width_m}")
    laps = spec.get("laps", 1)
    if isinstance(laps, bool) or not isinstance(laps, int):
        raise CourseError(f"'laps' must be a whole number of laps, got {laps!r}")
    try:
        stretches = tuple(WidthStretch(float(w["from_m"]), float(w["to_m"]),
                                       float(w["width_m"])) for w in widths)
        options = CourseOptions(
            trim=TrimOptions(start=parse_mark(spec.get("start")),
                             finish=parse_mark(spec.get("finish")), route=route),
            elevation=ElevationOptions(source=str(spec.get("elevation", "auto")),
                                       tolerance_m=float(spec.get("elevation_tolerance_m",
                                                                  5.0))),
            road_width_m=float(spec.get("road_width_m", GPS_ROAD_WIDTH_M)), widths=stretches,
            laps=laps)
    except (KeyError, TypeError, ValueError) as err:
        raise CourseError(f"invalid GPS-course field ({type(err).__name__}: {err})") from None
    return base / str(spec["track"]), options
