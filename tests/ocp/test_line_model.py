"""The 1D model that knows the corners of its line ("1dline", `model.dynamics.build_1d_line`):
through a tight corner its plan brakes before it, keeps C16 with the lateral acceleration
v^2 kappa of the line and pedals only below C15's lean; the verification checks its path
constraints; on the line of a 3D plan it predicts the 3D's finish; the plain 1D baseline
is unchanged by the road reaching the path constraints."""

from __future__ import annotations

import numpy as np
import pytest

from itt_planner.course.builder import build_course
from itt_planner.course.geometry import Course
from itt_planner.course.racing_line import offset_course
from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.dynamics import build_1d_line, steady_lean_rad
from itt_planner.model.params import lateral_limit_mps2
from itt_planner.model.rider import PRESETS
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.course_settings import OcpSettings, Start
from itt_planner.ocp.line_plan import line_corners, solve_rest_on_line
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.verify import node_curvature, verify_plan

RIDER = PRESETS["paper"]
RADIUS_M = 15.0
CORNER_M = (300.0, 300.0 + np.pi / 2 * RADIUS_M)  # where the bend is


def _hairpin() -> Course:
    """The small course of the 1D regression: 300 m at -3 %, a 12 m hairpin, 300 m at +2 %."""
    return build_course({"name": "hairpin-small", "segments": [
        {"type": "straight", "length_m": 300.0, "grade_pct": -3.0},
        {"type": "arc", "angle_deg": 180, "radius_m": 12.0, "direction": "left"},
        {"type": "straight", "length_m": 300.0, "grade_pct": 2.0}]})


def _bend() -> Course:
    """300 m downhill at -4 % into a 90-degree left bend of 15 m, 300 m level after."""
    return build_course({"name": "tight-bend", "segments": [
        {"type": "straight", "length_m": 300.0, "grade_pct": -4.0},
        {"type": "arc", "angle_deg": 90, "radius_m": RADIUS_M, "direction": "left"},
        {"type": "straight", "length_m": 300.0, "grade_pct": 0.0}]})


@pytest.fixture(scope="module")
def bend() -> Course:
    return _bend()


@pytest.fixture(scope="module")
def line_plan(bend: Course) -> Plan:
    plan = solve_plan(bend, RIDER, model="1dline")
    assert plan.meta["success"], plan.meta["attempts"]
    return plan


def test_plain_1d_is_unchanged() -> None:
    """The finish of the plain 1D on a small course before the road reached the path
    constraints (commit 0c205e4: 37.08545138753145 s, 15 iterations, 120 nodes)."""
    plan = solve_plan(_hairpin(), RIDER, model="1d")
    assert plan.meta["success"]
    assert plan.finish_time_s == pytest.approx(37.08545138753145, rel=1e-6)
    assert np.all(plan.ay_mps2 == 0.0)  # the baseline ignores corners (model.md 6)


def test_brakes_before_the_corner_within_c16(bend: Course, line_plan: Plan) -> None:
    plan = line_plan
    inside = (plan.s_m >= CORNER_M[0]) & (plan.s_m <= CORNER_M[1])
    before = (plan.s_m > CORNER_M[0] - 100.0) & (plan.s_m < CORNER_M[0])
    # The lateral acceleration is v^2 kappa, the curvature over the node's two intervals.
    turn, h = np.diff(bend.at("theta_rad", plan.s_m)), np.diff(plan.s_m)
    kappa = (np.append(0, turn) + np.append(turn, 0)) / (np.append(0, h) + np.append(h, 0))
    assert kappa == pytest.approx(node_curvature(bend, plan.s_m))
    assert plan.ay_mps2 == pytest.approx(plan.v_mps ** 2 * kappa, rel=1e-9, abs=1e-9)
    limit = lateral_limit_mps2(RIDER, Conditions())
    assert np.max(np.abs(plan.ay_mps2[inside])) == pytest.approx(limit, rel=0.02)  # at grip
    assert np.max(plan.friction_use) <= 1.0 + 1e-6  # C16
    # It brakes into the bend, down to the speed the grip allows round it.
    assert np.min(plan.w_n[before]) < -0.1
    assert np.max(plan.v_mps[inside]) <= np.sqrt(limit * RADIUS_M) * 1.01
    assert np.max(plan.v_mps[before]) > 1.3 * np.max(plan.v_mps[inside])
    # C15: pedalling only where the steady lean is below the pedalling limit.
    lean = np.abs(steady_lean_rad(plan.ay_mps2))
    pedalling = plan.w_n > 0.05
    assert np.any(pedalling) and np.all(lean[pedalling] < RIDER.pedal_lean_max_rad)
    assert np.all(plan.w_n[lean > RIDER.pedal_lean_max_rad] <= 0.02)


def test_plain_1d_rides_the_corner_beyond_the_grip(bend: Course, line_plan: Plan) -> None:
    """The baseline on the same course: faster, because it takes the bend at a lateral
    acceleration no tyre gives; the verification with the 1D-line model's path
    constraints says so, and passes the 1D-line plan."""
    plain = solve_plan(bend, RIDER, model="1d")
    assert plain.finish_time_s < line_plan.finish_time_s - 1.0
    model = build_1d_line()
    check = verify_plan(plain, bend, RIDER, model=model)
    assert not check.verified and check.worst == "path"
    assert CORNER_M[0] - 5.0 <= check.worst_s_m <= CORNER_M[1] + 5.0
    assert check.max_path_violation > 1.0  # the friction use squared above 2
    own = verify_plan(line_plan, bend, RIDER, model=model)
    assert own.verified and own.max_path_violation < 0.04


def test_on_the_line_of_a_3d_plan_it_is_close_to_the_3d(bend: Course) -> None:
    """The rest of the course from the 3D plan's own state at 200 m, solved on the 3D
    plan's line: rideable by `line_corners`, and a few % slower than the 3D (measured
    2026-12-03: +7.1 %, 24.70 s against 23.06 s; 2026-12-04, +9.8 %, 25.31 s, another
    local optimum of the 1D-line NLP, braking later and deeper, when the 3D plan's finish
    was held upright and its line moved 0.09 m on the last straight): through the bend
    it brakes and turns
    at once within the friction ellipse at the steady lean of C15 (7.5-7.8 m/s^2
    sideways against the 3D's 9.8, 14.0-14.5 m/s against 16.1-16.6), the steady lean
    stops the pedalling where the line's lateral acceleration peaks, and the power rate
    limit (E6) then slows the ramp back up. (+3.5 % on 2026-12-02 was on the line's
    heading differentiated from its polyline resampled onto its own grid, whose
    curvature aliased, alternating 0.003 and 0.026 1/m after the bend: on another machine
    that line's plan rode an artefact, 1.5 to 8 m/s within 3 m, and was invalid.)"""
    plan_3d = solve_plan(bend, RIDER, model="3d")
    assert plan_3d.meta["success"]
    line = offset_course(bend, np.interp(bend.s_m, plan_3d.s_m, plan_3d.n_m), "3d line")
    s0 = 200.0
    start = Start(s_m=s0, state={k: float(plan_3d.at(a, s0))
                                 for k, a in (("v", "v_mps"), ("w_n", "w_n"), ("e_n", "e_n"))})
    rest, point = solve_rest_on_line(line, RIDER, Conditions(), OcpSettings(), guess=plan_3d,
                                     start=start)
    assert rest.meta["success"] and point is not None and rest.model == "1dline"
    rest_3d = plan_3d.finish_time_s - float(plan_3d.at("t_s", s0))
    assert rest_3d * 0.995 < rest.finish_time_s < rest_3d * 1.11
    fitted, why = line_corners(rest, line, RIDER, Conditions())
    assert why == ""
    assert np.max(np.abs(fitted.ay_mps2)) > 0.8 * GRAVITY_MPS2  # it does corner at grip
