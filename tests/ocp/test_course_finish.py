"""The finish of a 3D plan: model.md leaves the end state free, so nothing after the line
pays for how the rider crosses it. With the lean free there too, a plan whose line is
drawn in a bend crossed it falling outwards (58 deg at 224 deg/s, against the bend)."""

from __future__ import annotations

import math

import numpy as np

from itt_planner.course.builder import build_course
from itt_planner.model.rider import PRESETS
from itt_planner.ocp.course_problem import solve_plan


def test_a_finish_in_a_bend_is_crossed_leaning_into_it_within_the_grip() -> None:
    course = build_course({"name": "finish-in-a-bend", "width_left_m": 4.0,
                           "width_right_m": 4.0, "segments": [
                               {"type": "straight", "length_m": 300.0},
                               {"type": "clothoid", "length_m": 10.0, "radius_m": 12.0,
                                "direction": "left"},
                               {"type": "arc", "angle_deg": 60.0, "radius_m": 12.0,
                                "direction": "left"}]})
    plan = solve_plan(course, PRESETS["typical"], model="3d")
    assert plan.converged, plan.solver_status
    grip_lean = math.atan(1.0)  # dry road, mu_y = 1 (C16)
    assert abs(plan.phi_rad[-1]) <= grip_lean + 1e-6
    assert plan.phi_dot_radps[-1] == 0.0
    # A left bend: leaning left (phi < 0, model.md E5) at the line, not falling outwards.
    assert plan.phi_rad[-1] < 0.0
    assert np.max(np.abs(plan.phi_rad)) <= grip_lean + 0.02
