"""Small synthetic courses for the OCP tests (a hairpin, a straight) and course-builder
specs shared with the benchmarks."""

from __future__ import annotations

from typing import Any

import numpy as np

from itt_planner.course.geometry import Course, GeoOrigin


def hairpin(straight_m: float = 300.0, radius_m: float = 12.0, width_m: float = 4.0) -> Course:
    """A straight, a 180 deg hairpin of `radius_m`, a straight back (flat)."""
    a = np.arange(0.0, straight_m, 1.0)
    th = np.linspace(-np.pi / 2, np.pi / 2, int(np.pi * radius_m) + 1)[1:]
    b = np.arange(1.0, straight_m, 1.0)
    x = np.concatenate([a, straight_m + radius_m * np.cos(th), straight_m - b])
    y = np.concatenate([0 * a, radius_m + radius_m * np.sin(th), np.full_like(b, 2 * radius_m)])
    return Course.from_centerline("hairpin", x, y, np.zeros_like(x), origin=GeoOrigin(45, 11, 0),
                                  width_left_m=width_m, width_right_m=width_m, synthetic=True)


def straight(length_m: float = 1500.0) -> Course:
    x = np.arange(0.0, length_m, 1.0)
    return Course.from_centerline("straight", x, 0 * x, 0 * x, origin=GeoOrigin(45, 11, 0))


def climb_bend_descent(name: str, climb_m: float) -> dict[str, object]:
    """Course-builder spec: a 2 % climb of `climb_m`, a 14 m hairpin-like bend, 250 m of
    -3 % descent (3D solves ~1 s CPU each)."""
    return {"name": name, "width_left_m": 4.0, "width_right_m": 4.0, "segments": [
        {"type": "straight", "length_m": climb_m, "grade_pct": 2.0},
        {"type": "clothoid", "length_m": 10.0, "radius_m": 14.0, "direction": "left",
         "grade_pct": -3.0},
        {"type": "arc", "angle_deg": 120.0, "radius_m": 14.0, "direction": "left",
         "grade_pct": -3.0},
        {"type": "clothoid", "length_m": 10.0, "grade_pct": -3.0},
        {"type": "straight", "length_m": 250.0, "grade_pct": -3.0}]}


def switchback_climb() -> dict[str, object]:
    """Course-builder spec: six 15 m switchbacks up 7 % ramps of 80 m (1.16 km, a 5 m
    road), as the Suunto watch's circuit of the horizon's switchback tests."""
    segments: list[dict[str, object]] = [{"type": "straight", "length_m": 200.0,
                                          "grade_pct": 2.0}]
    for k in range(6):
        segments += [{"type": "straight", "length_m": 80.0, "grade_pct": 7.0},
                     {"type": "arc", "angle_deg": 180.0, "radius_m": 15.0,
                      "direction": "left" if k % 2 else "right", "grade_pct": 5.0}]
    segments.append({"type": "straight", "length_m": 200.0, "grade_pct": 2.0})
    return {"name": "switchback-climb", "width_left_m": 2.5, "width_right_m": 2.5,
            "segments": segments}


#: The sweep tests' and bench's short course, 1.2 km.
SHORT = climb_bend_descent("short-1200m", 900.0)


def loop_4k_lap() -> list[dict[str, Any]]:
    """Course-builder segments of one lap of issue 18's 4 km loop (bench_convergence's
    `loop-4k-2laps` is two of them): four left corners of 20 m entered and left through
    clothoids."""
    out: list[dict[str, Any]] = []
    for side in (900.0, 1037.0, 900.0, 1037.0):
        out += [{"type": "straight", "length_m": side},
                {"type": "clothoid", "length_m": 10, "radius_m": 20, "direction": "left"},
                {"type": "arc", "angle_deg": 90 - 28.65, "radius_m": 20, "direction": "left"},
                {"type": "clothoid", "length_m": 10}]
    return out
