"""Segment YAML -> course: geometry of the primitives, the demo courses, errors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from itt_planner.course.builder import FAKE_ORIGIN, build_course, build_course_file
from itt_planner.course.geometry import Course, GeoOrigin
from itt_planner.course.loader import load_course
from itt_planner.errors import CourseError
from itt_planner.sim import hairpin_course


def test_arc_and_clothoid_geometry() -> None:
    course = build_course({"segments": [
        {"type": "straight", "length_m": 100},
        {"type": "clothoid", "length_m": 20, "radius_m": 20, "direction": "left"},
        {"type": "arc", "angle_deg": 90, "radius_m": 20, "direction": "left", "grade_pct": 5},
        {"type": "clothoid", "length_m": 20},
        {"type": "straight", "length_m": 100, "grade": -0.02, "width_left_m": 2.5},
    ]})
    assert course.synthetic and course.origin == FAKE_ORIGIN
    arc = math.radians(90) * 20
    assert course.length_m == pytest.approx(100 + 20 + arc + 20 + 100, abs=1.0)
    # Total turn = arc + half of each clothoid (kappa ramps linearly).
    turn = course.theta_rad[-1] - course.theta_rad[0]
    assert turn == pytest.approx(math.pi / 2 + 2 * 0.5 * 20 / 20, abs=1e-3)
    assert course.kappa_per_m.max() == pytest.approx(1 / 20, rel=1e-3)
    # Curvature is continuous (clothoids), no step bigger than one grid step of the ramp.
    assert np.abs(np.diff(course.kappa_per_m)).max() < 1.1 * (1 / 20) / 20
    assert course.z_m[-1] == pytest.approx(0.05 * arc - 0.02 * 100, abs=0.05)
    assert course.width_left_m[-1] == 2.5 and course.width_right_m[-1] == 4.0
    (corner,) = course.corners
    assert corner.direction == "left"
    assert corner.min_radius_m == pytest.approx(20.0, rel=0.01)


@pytest.mark.parametrize(("name", "length_m", "gain_m", "n_corners"), [
    ("verona-like", 16_800.0, 205.0, 19),
    ("rovereto-like", 34_200.0, 214.0, 6),
])
def test_demo_courses_match_published_facts(name: str, length_m: float, gain_m: float,
                                            n_corners: int) -> None:
    info = load_course(name).summary()
    assert info["synthetic"] is True
    assert info["length_m"] == pytest.approx(length_m, rel=0.01)
    assert info["gain_m"] == pytest.approx(gain_m, rel=0.01)
    assert info["n_corners"] == n_corners


def test_verona_like_descent_has_13_turns_with_hairpins() -> None:
    course = load_course("verona-like")
    descent_start = 4_200.0 + 4_500.0
    turns = [c for c in course.corners if descent_start <= c.apex_s_m <= descent_start + 4_700.0]
    assert len(turns) == 13
    hairpins = [c for c in turns if c.angle_rad > math.radians(150)]
    assert len(hairpins) >= 5
    assert all(10.0 <= c.min_radius_m <= 15.0 for c in hairpins)
    climb = (course.s_m > 4_250) & (course.s_m < 8_650)
    assert np.tan(course.beta_rad[climb]).mean() == pytest.approx(0.0456, abs=0.002)


def test_save_load_round_trip(tmp_path: Path) -> None:
    course = load_course("rovereto-like")
    again = Course.load(course.save(tmp_path / "r.course.npz"))
    assert again.summary() == course.summary()
    assert np.array_equal(again.kappa_per_m, course.kappa_per_m)
    assert load_course(tmp_path / "r.course.npz").length_m == course.length_m


@pytest.mark.parametrize(("segments", "problem"), [
    ([], "empty"),
    ([{"type": "spiral", "length_m": 5}], "'type' must be one of"),
    ([{"type": "straight"}], "'length_m' is required"),
    ([{"type": "straight", "length_m": -3}], "positive"),
    ([{"type": "arc", "radius_m": 10, "angle_deg": 90, "direction": "up"}], "direction"),
    ([{"type": "straight", "length_m": 10, "grade": 5}], "not a road"),
    ([{"type": "straight", "length_m": 10, "grade": 0.1, "grade_pct": 10}], "not both"),
    ([{"type": "straight", "length_m": 10, "colour": "red"}], "unknown field"),
])
def test_invalid_segments_are_named(segments: list[dict[str, object]], problem: str) -> None:
    with pytest.raises(CourseError, match=problem):
        build_course({"segments": segments})


def test_bad_yaml_file_names_the_file(tmp_path: Path) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text("segments: [ {type: straight, length_m: 10}\n")
    with pytest.raises(CourseError, match=r"broken\.yaml"):
        build_course_file(path)


def test_unknown_course_spec() -> None:
    with pytest.raises(CourseError, match="unknown course"):
        load_course("giro-2030")


def test_a_full_circle_is_a_warning() -> None:
    """A track that rides round a 6 m circle twice between two straights (GPS wandering
    while standing does the same) makes a 720 deg "corner": `course info` says so; a
    hairpin's 180 deg does not."""
    a = np.linspace(0.0, 4 * math.pi, 400)
    x = np.concatenate([np.linspace(-200.0, -1.0, 200), 6.0 * np.sin(a),
                        np.linspace(1.0, 200.0, 200)])
    y = np.concatenate([np.zeros(200), 6.0 - 6.0 * np.cos(a), np.zeros(200)])
    loop = Course.from_centerline("loops", x, y, 0 * x, origin=GeoOrigin(45.0, 11.0, 0.0))
    [warning] = loop.summary()["warnings"]
    assert "turns 7" in warning and "no road" in warning
    assert hairpin_course().summary()["warnings"] == []


def test_a_double_apex_bend_is_one_corner() -> None:
    """Two tight arcs of one direction joined by a wider one (150 m: under twice the
    corner radius, so one bend): one corner of the whole bend's angle, its apex the
    tighter arc's. Each arc was a corner of its own with the whole bend's angle, their
    spans overlapping (a phone's mountain-bike ride listed a 149 deg bend twice)."""
    arc = {"type": "arc", "direction": "right"}
    course = build_course({"name": "double-apex", "segments": [
        {"type": "straight", "length_m": 200.0},
        arc | {"angle_deg": 60.0, "radius_m": 25.0},
        arc | {"angle_deg": 20.0, "radius_m": 150.0},
        arc | {"angle_deg": 60.0, "radius_m": 15.0},
        {"type": "straight", "length_m": 200.0}]})
    [corner] = course.corners
    assert math.degrees(corner.angle_rad) == pytest.approx(140.0, abs=3.0)
    assert corner.min_radius_m == pytest.approx(15.0, rel=0.05)
    assert corner.direction == "right"
