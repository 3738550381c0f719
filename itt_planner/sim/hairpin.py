"""The hairpin test course: a short synthetic technical course (a hairpin, a road crossing
itself, an S-bend) for the closed-loop tests and the CLI's quick runs."""

from __future__ import annotations

from itt_planner.course.builder import build_course
from itt_planner.course.geometry import Course

#: Segments (course_builder format) of `hairpin_course`: a climb, a 270 deg bend whose
#: exit crosses the first straight, a 12 m hairpin on a descent, an S-bend.
HAIRPIN_COURSE = {
    "name": "hairpin-test",
    "description": "SYNTHETIC ~2.8 km technical test course of the closed-loop tests.",
    "origin": {"lat_deg": 45.43, "lon_deg": 10.99, "alt_m": 100.0},
    "segments": [
        {"type": "straight", "length_m": 500, "grade_pct": 2},
        {"type": "clothoid", "length_m": 15, "radius_m": 50, "direction": "left"},
        {"type": "arc", "angle_deg": 253, "radius_m": 50, "direction": "left"},
        {"type": "clothoid", "length_m": 15},
        {"type": "straight", "length_m": 400, "grade_pct": -1},
        {"type": "clothoid", "length_m": 12, "radius_m": 30, "direction": "right"},
        {"type": "arc", "angle_deg": 67, "radius_m": 30, "direction": "right"},
        {"type": "clothoid", "length_m": 12},
        {"type": "straight", "length_m": 300, "grade_pct": -3},
        {"type": "clothoid", "length_m": 10, "radius_m": 12, "direction": "left", "grade_pct": -3},
        {"type": "arc", "angle_deg": 130, "radius_m": 12, "direction": "left"},
        {"type": "clothoid", "length_m": 10},
        {"type": "straight", "length_m": 500, "grade_pct": 1},
        {"type": "clothoid", "length_m": 10, "radius_m": 40, "direction": "right"},
        {"type": "arc", "angle_deg": 30, "radius_m": 40, "direction": "right"},
        {"type": "clothoid", "length_m": 20, "radius_m": 40, "direction": "left"},
        {"type": "arc", "angle_deg": 30, "radius_m": 40, "direction": "left"},
        {"type": "clothoid", "length_m": 10},
        {"type": "straight", "length_m": 600},
    ],
}


def hairpin_course(ds_m: float = 1.0) -> Course:
    """The ~2.8 km synthetic technical course `HAIRPIN_COURSE` (course_builder)."""
    return build_course(HAIRPIN_COURSE, source="itt_planner.sim.hairpin.HAIRPIN_COURSE",
                        ds_m=ds_m)
