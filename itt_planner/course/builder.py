"""Segment descriptions (YAML) -> `Course`, for what-if studies and the demo courses.

A course file is a mapping::

    name: verona-like
    description: free text (say where the numbers come from)
    origin: {lat_deg: 45.44, lon_deg: 10.99, alt_m: 60.0}   # optional
    width_left_m: 4.0                                      # optional defaults
    width_right_m: 4.0
    segments:
      - {type: straight, length_m: 800, grade_pct: 0}
      - {type: clothoid, length_m: 15, radius_m: 12, direction: left}   # ramp into a bend
      - {type: arc, angle_deg: 150, radius_m: 12, direction: left, grade: -0.05}
      - {type: clothoid, length_m: 15}                                  # ramp back to straight

Segment types (lengths are horizontal arc length in metres):

- `straight`: `length_m`.
- `arc`: constant curvature 1/`radius_m`, turning `direction` (left/right); `length_m` or
  `angle_deg` (the turn).
- `clothoid`: curvature changes linearly over `length_m` from where the previous segment
  ended to 1/`radius_m` in `direction`, or to zero (straight) when no radius is given.
  Entering and leaving arcs through clothoids keeps curvature continuous, which the OCP's
  lateral dynamics need.

Grade is per segment and constant along it: `grade` is a FRACTION (0.05 = 5 %),
`grade_pct` a percentage; give at most one (default 0). Optional per-segment
`width_left_m` / `width_right_m` override the defaults.

Heading is integrated analytically (theta = theta0 + kappa0*s + kappa'*s^2/2 per segment);
positions by midpoint quadrature on a 0.25 m step (error far below a millimetre per km).

Built courses are marked `synthetic=True`. They have no geodetic position of their own:
the ENU frame is anchored at `origin` if given, else at a fixed FAKE origin (0 N, 0 E,
0 m: the Gulf of Guinea), so that lat/lon output is well defined but obviously not a real
place.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from itt_planner.course.geometry import DEFAULT_HALF_WIDTH_M, Course, GeoOrigin
from itt_planner.course.track_files import file_sha256
from itt_planner.errors import CourseError

#: Anchor of built courses without an `origin`: deliberately not a road anywhere.
FAKE_ORIGIN = GeoOrigin(lat_deg=0.0, lon_deg=0.0, alt_m=0.0)
_STEP_M = 0.25
_KINDS = ("straight", "arc", "clothoid")
_KEYS = {"type", "length_m", "angle_deg", "radius_m", "direction", "grade", "grade_pct",
         "width_left_m", "width_right_m", "note"}


@dataclass(frozen=True)
class Segment:
    """One validated segment. Curvatures in 1/m (positive = left), grade as a fraction."""

    kind: str
    length_m: float
    kappa_end_per_m: float
    grade: float
    width_left_m: float
    width_right_m: float


def build_course_file(path: str | Path) -> Course:
    """Read a segment YAML file and build the course.

    Raises:
        CourseError: unreadable YAML or an invalid segment (names the file and segment).
    """
    path = Path(path)
    try:
        spec = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as err:
        raise CourseError(f"{path}: could not read course YAML ({err})") from None
    try:
        course = build_course(spec, source=str(path))
    except CourseError as err:
        raise CourseError(f"{path}: {err}") from None
    return dataclasses.replace(course, source_sha256=file_sha256(path))


def build_course(spec: Any, *, source: str = "", ds_m: float = 1.0) -> Course:
    """Build a course from an already parsed segment description (see module docstring).

    Raises:
        CourseError: missing or invalid fields, naming the segment.
    """
    if not isinstance(spec, dict) or not isinstance(spec.get("segments"), list):
        raise CourseError("expected a mapping with a 'segments' list")
    if not spec["segments"]:
        raise CourseError("'segments' is empty")
    wl0 = _number(spec, "width_left_m", "course", DEFAULT_HALF_WIDTH_M, positive=True)
    wr0 = _number(spec, "width_right_m", "course", DEFAULT_HALF_WIDTH_M, positive=True)
    origin = FAKE_ORIGIN
    if spec.get("origin") is not None:
        try:
            origin = GeoOrigin(**{k: float(v) for k, v in spec["origin"].items()})
        except (TypeError, ValueError, AttributeError) as err:
            raise CourseError(f"origin: expected lat_deg, lon_deg, alt_m ({err})") from None
    segments = [_segment(raw, i, wl0, wr0) for i, raw in enumerate(spec["segments"])]
    x, y, z, theta, kap, wl, wr = _integrate(segments)
    return Course.from_centerline(
        str(spec.get("name", "built")), x, y, z, origin=origin, ds_m=ds_m,
        width_left_m=wl, width_right_m=wr, theta_rad=theta, kappa_per_m=kap,
        source=source, synthetic=True,
    )


def _number(raw: dict[str, Any], key: str, where: str, default: float | None = None, *,
            positive: bool = False) -> float:
    value = raw.get(key, default)
    if value is None:
        raise CourseError(f"{where}: '{key}' is required")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise CourseError(f"{where}: '{key}' must be a number, got {value!r}") from None
    if not math.isfinite(number) or (positive and number <= 0):
        raise CourseError(f"{where}: '{key}' must be a positive finite number, got {value!r}")
    return number


def _segment(raw: Any, i: int, wl0: float, wr0: float) -> Segment:
    where = f"segment {i + 1}"
    if not isinstance(raw, dict):
        raise CourseError(f"{where}: expected a mapping, got {raw!r}")
    unknown = sorted(set(raw) - _KEYS)
    if unknown:
        raise CourseError(f"{where}: unknown field(s) {', '.join(unknown)}")
    kind = raw.get("type")
    if kind not in _KINDS:
        raise CourseError(f"{where}: 'type' must be one of {', '.join(_KINDS)}, got {kind!r}")
    where = f"{where} ({kind})"
    if "grade" in raw and "grade_pct" in raw:
        raise CourseError(f"{where}: give 'grade' (fraction) or 'grade_pct', not both")
    grade = (_number(raw, "grade_pct", where) / 100.0 if "grade_pct" in raw
             else _number(raw, "grade", where, 0.0))
    if abs(grade) > 0.3:
        raise CourseError(f"{where}: grade {grade:.3f} is not a road (|grade| <= 0.3; "
                          "'grade' is a fraction, use 'grade_pct' for percent)")
    sign = 0.0
    if "radius_m" in raw:
        direction = raw.get("direction")
        if direction not in ("left", "right"):
            raise CourseError(f"{where}: 'direction' must be left or right, got {direction!r}")
        sign = 1.0 if direction == "left" else -1.0
    wl = _number(raw, "width_left_m", where, wl0, positive=True)
    wr = _number(raw, "width_right_m", where, wr0, positive=True)
    if kind == "straight":
        return Segment(kind, _number(raw, "length_m", where, positive=True), 0.0, grade, wl, wr)
    if kind == "arc":
        radius = _number(raw, "radius_m", where, positive=True)
        if "angle_deg" in raw:
            length = math.radians(_number(raw, "angle_deg", where, positive=True)) * radius
        else:
            length = _number(raw, "length_m", where, positive=True)
        return Segment(kind, length, sign / radius, grade, wl, wr)
    kappa_end = sign / _number(raw, "radius_m", where, positive=True) if sign else 0.0
    return Segment(kind, _number(raw, "length_m", where, positive=True), kappa_end, grade,
                   wl, wr)


def _integrate(segments: list[Segment]) -> tuple[np.ndarray, ...]:
    """Dense centre line: x, y, z, heading, curvature, widths at every `_STEP_M`."""
    xs, ys, zs, ths, ks, wls, wrs = ([np.zeros(1)] for _ in range(7))
    x = y = z = theta = kappa0 = 0.0
    wls[0][0], wrs[0][0] = segments[0].width_left_m, segments[0].width_right_m
    for seg in segments:
        n = max(1, math.ceil(seg.length_m / _STEP_M))
        s = np.linspace(0.0, seg.length_m, n + 1)[1:]
        if seg.kind == "clothoid":
            rate = (seg.kappa_end_per_m - kappa0) / seg.length_m
        else:
            rate = 0.0
            kappa0 = seg.kappa_end_per_m if seg.kind == "arc" else 0.0
        th = theta + kappa0 * s + 0.5 * rate * s**2
        h = seg.length_m / n
        th_mid = theta + kappa0 * (s - h / 2) + 0.5 * rate * (s - h / 2) ** 2
        xs.append(x + np.cumsum(h * np.cos(th_mid)))
        ys.append(y + np.cumsum(h * np.sin(th_mid)))
        zs.append(z + seg.grade * s)
        ths.append(th)
        ks.append(kappa0 + rate * s)
        wls.append(np.full(n, seg.width_left_m))
        wrs.append(np.full(n, seg.width_right_m))
        x, y, z, theta = float(xs[-1][-1]), float(ys[-1][-1]), float(zs[-1][-1]), float(th[-1])
        kappa0 = seg.kappa_end_per_m
    return tuple(np.concatenate(a) for a in (xs, ys, zs, ths, ks, wls, wrs))
