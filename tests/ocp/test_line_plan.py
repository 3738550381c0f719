"""The shortest line within the road (`course.racing_line`) and the 1D plan on it
(`ocp.line_plan`): the line's length against the exact taut string around a bend, and a
1D plan on the line that is verified, spans the road and is faster by its shorter path."""

from __future__ import annotations

import math

import numpy as np
import pytest

from itt_planner.course.builder import build_course
from itt_planner.course.geometry import Course
from itt_planner.course.racing_line import line_course, shortest_line
from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.dynamics import build_3d_steady_lean
from itt_planner.model.rider import Rider
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.horizon_settings import HorizonSettings
from itt_planner.ocp.horizon_window import HorizonWindow
from itt_planner.ocp.line_plan import solve_plan_on_line

MARGIN_M = 0.5
RADIUS_M = 30.0
STRAIGHT_M = 300.0


def _u_turn(grade_pct: float = 0.0) -> Course:
    """300 m straight, a 180-degree left bend of 30 m radius, 300 m straight; 8 m road."""
    return build_course({"name": "u-turn", "segments": [
        {"type": "straight", "length_m": STRAIGHT_M, "grade_pct": grade_pct},
        {"type": "arc", "angle_deg": 180, "radius_m": RADIUS_M, "direction": "left",
         "grade_pct": grade_pct},
        {"type": "straight", "length_m": STRAIGHT_M, "grade_pct": grade_pct}]})


def _taut_string_m() -> float:
    """The shortest path from the start (centre line) to the finish line of `_u_turn`:
    tangent to the inner edge circle, round it, then along the inner edge."""
    inner = RADIUS_M - (4.0 - MARGIN_M)
    cx, cy = STRAIGHT_M, RADIUS_M
    dist = math.hypot(cx, cy)
    tangent = math.sqrt(dist * dist - inner * inner)
    touch = math.atan2(-cy, -cx) + math.acos(inner / dist)  # counter-clockwise from here
    leave = math.pi / 2
    arc = inner * ((leave - touch) % (2 * math.pi))
    return tangent + arc + STRAIGHT_M


def test_shortest_line_is_the_taut_string() -> None:
    course = _u_turn()
    n, _, stretch = shortest_line(course, MARGIN_M)
    assert n[0] == 0.0
    assert np.all(n <= course.width_left_m - MARGIN_M + 1e-9)
    assert np.all(n >= -(course.width_right_m - MARGIN_M) - 1e-9)
    line = line_course(course, MARGIN_M)
    exact = _taut_string_m()
    assert line.s_line_m[-1] == pytest.approx(exact, rel=5e-4)
    assert line.course.length_m == pytest.approx(line.s_line_m[-1], abs=1e-6)
    # the stretch (E8) integrates to the same length
    mid = 0.5 * (stretch[1:] + stretch[:-1])
    assert float(np.sum(np.diff(course.s_m) * mid)) == pytest.approx(exact, rel=1e-3)
    # round the bend it hugs the inner edge
    apex = np.argmin(np.abs(course.s_m - (STRAIGHT_M + math.pi * RADIUS_M / 2)))
    assert n[apex] == pytest.approx(4.0 - MARGIN_M)


def test_straight_road_keeps_the_centre_line() -> None:
    course = build_course({"name": "straight", "segments": [
        {"type": "straight", "length_m": 500, "grade_pct": 3}]})
    line = line_course(course, MARGIN_M)
    assert np.allclose(line.n_m, 0.0)
    assert line.length_ratio == pytest.approx(1.0)
    assert line.course.z_m[-1] == pytest.approx(course.z_m[-1])


def test_1d_plan_on_the_line() -> None:
    course = _u_turn(grade_pct=1.0)
    rider = Rider()
    centre = solve_plan(course, rider, model="1d")
    plan = solve_plan_on_line(course, rider)
    assert plan.converged and plan.meta["verification"]["verified"]
    assert plan.s_m[0] == 0.0 and plan.s_m[-1] == pytest.approx(course.length_m)
    assert np.all(np.diff(plan.s_m) > 0)
    ratio = plan.meta["line"]["length_ratio"]
    assert ratio == pytest.approx(_taut_string_m() / course.length_m, rel=1e-3)
    # same physics over a shorter path: faster, by about the path (the climb is the same)
    assert plan.finish_time_s < centre.finish_time_s
    assert plan.finish_time_s / centre.finish_time_s == pytest.approx(ratio, abs=0.005)
    assert np.max(np.abs(plan.n_m)) == pytest.approx(4.0 - MARGIN_M)
    assert plan.point_w is None


def test_plan_on_the_line_that_knows_its_corners() -> None:
    """`corners=True`: the 1D model that knows the line's corners ("1dline") on the same
    shortest line: slower than the baseline round the 26.5 m inner edge, where it keeps
    C16 (friction use <= 1) and does not pedal beyond C15's lean; the steady turn's lean
    and steering are in the plan (a 3D re-solve's guess)."""
    course = _u_turn(grade_pct=1.0)
    rider = Rider()
    plain = solve_plan_on_line(course, rider)
    plan = solve_plan_on_line(course, rider, corners=True)
    assert plan.model == "1dline" and plan.meta["success"], plan.meta["attempts"]
    assert plan.meta["line"]["length_ratio"] == pytest.approx(plain.meta["line"]["length_ratio"])
    assert plan.finish_time_s > plain.finish_time_s + 0.5
    assert np.max(plan.friction_use) <= 1.0 + 1e-6
    assert np.max(np.abs(plan.ay_mps2)) > GRAVITY_MPS2 * np.tan(rider.pedal_lean_max_rad)
    lean = np.abs(plan.phi_rad)
    assert lean == pytest.approx(np.abs(np.arctan(plan.ay_mps2 / GRAVITY_MPS2)))
    assert np.all(plan.w_n[lean > rider.pedal_lean_max_rad] <= 0.02)
    bend = (plan.s_m > STRAIGHT_M + 10) & (plan.s_m < STRAIGHT_M + math.pi * RADIUS_M - 10)
    assert np.all(plan.delta_n[bend] > 0)  # steering left round the left bend


def test_a_horizon_from_the_line_plan_steers_along_the_line() -> None:
    """A receding horizon over a "1dline" plan starts from the plan's steady turn on the
    line (as a 3D re-solve does, `guess.plan_guess`), not from the centre line's: round
    the U-turn the line is tighter than the 30 m centre line."""
    course = _u_turn(grade_pct=1.0)
    rider = Rider()
    plan = solve_plan_on_line(course, rider, corners=True)
    window = HorizonWindow(build_3d_steady_lean(), course, rider, plan, Conditions(),
                           HorizonSettings(horizon_m=400.0))
    nodes = window.nodes(STRAIGHT_M - 100.0)
    x, _ = window.plan_guess(nodes)
    steering = x[window.model.index("delta_n")]
    assert steering == pytest.approx(plan.at("delta_n", nodes))
    centre = np.arctan(rider.wheelbase_m / RADIUS_M) / rider.steer_max_rad
    assert np.max(steering) > 1.05 * centre
