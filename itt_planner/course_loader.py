"""Resolve any `--course` argument to a `Course`.

Accepted: a demo name (`verona-like`, `rovereto-like`: segment YAML shipped in
`itt_planner/data/`), a saved course (`*.course.npz`), a segment YAML file (`*.yaml`), or
a GPS track (`.gpx`, `.tcx`, `.fit`, `.csv`), which is fitted by `course_fit`.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from itt_planner.course import COURSE_SUFFIX, Course
from itt_planner.course_builder import build_course_file
from itt_planner.course_fit import fit_course_file
from itt_planner.errors import CourseError
from itt_planner.track_files import SUFFIXES

DEMO_COURSES = ("verona-like", "rovereto-like")


def demo_path(name: str) -> Path:
    """Path of a shipped demo course's segment YAML."""
    return Path(str(resources.files("itt_planner") / "data" / f"{name}.yaml"))


def load_course(spec: str | Path) -> Course:
    """Build or read the course named by `spec`.

    Raises:
        CourseError: unknown name, missing file, unsupported suffix, or a file that cannot
            be turned into a course (the message names the file and the problem).
    """
    text = str(spec)
    if text in DEMO_COURSES and not Path(text).exists():
        return build_course_file(demo_path(text))
    path = Path(text)
    name = path.name.lower()
    if name.endswith(COURSE_SUFFIX):
        if not path.is_file():
            raise CourseError(f"{path}: no such file")
        return Course.load(path)
    if path.suffix.lower() in (".yaml", ".yml"):
        if not path.is_file():
            raise CourseError(f"{path}: no such file")
        return build_course_file(path)
    if path.suffix.lower() in SUFFIXES:
        return fit_course_file(path)
    if not path.exists():
        msg = (f"unknown course {text!r}: not a demo ({', '.join(DEMO_COURSES)}) nor a file")
        raise CourseError(msg)
    msg = (f"{path}: unsupported course file; expected {', '.join(SUFFIXES)}, "
           f"{COURSE_SUFFIX} or a segment .yaml")
    raise CourseError(msg)
