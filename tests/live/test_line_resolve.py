"""Re-solves of the rest of the course with the 1D model on the line of the plan in
force (`live.resolve_model`, `ocp.line_plan.solve_rest_on_line`, `racing_line.offset_course`):
a verified plan on the road's arc length with the line's offset, warm from the previous
such re-solve; rideable round a tight corner (C15/C16 at the steady lean, the model
`build_1d_line`), and through the worker process with the model each re-solve used
stated."""

from __future__ import annotations

import dataclasses
from collections import Counter

import numpy as np
import pytest

from itt_planner.course.builder import build_course
from itt_planner.course.geometry import Course
from itt_planner.course.racing_line import offset_course
from itt_planner.live import resolve_model
from itt_planner.live.course_replan import CourseReplanner, CourseReplanSettings
from itt_planner.live.plan_in_force import PlanInForce
from itt_planner.live.resolve_model import (
    RESOLVE_1D_LINE,
    RESOLVE_3D,
    RESOLVE_AUTO,
    LineCache,
    Warm,
    on_line,
    solve_rest,
)
from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.rider import PRESETS
from itt_planner.ocp.cache import solve_keeping_point
from itt_planner.ocp.course_settings import OcpSettings, Start
from itt_planner.ocp.line_plan import line_corners, solve_plan_on_line, solve_rest_on_line
from itt_planner.ocp.plan import Plan

RIDER = PRESETS["paper"]
START_M = 400.0


def _bend(radius_m: float) -> Course:
    """400 m straight at +2 %, a 90-degree left bend of `radius_m`, 500 m straight at -1 %."""
    return build_course({"name": f"bend-{radius_m:.0f}", "segments": [
        {"type": "straight", "length_m": 400.0, "grade_pct": 2.0},
        {"type": "arc", "angle_deg": 90, "radius_m": radius_m, "direction": "left"},
        {"type": "straight", "length_m": 500.0, "grade_pct": -1.0}]})


GENTLE = _bend(400.0)


@pytest.fixture(scope="module")
def plan() -> Plan:
    """The plan in force: the 1D plan on the shortest line (a line off the centre)."""
    plan = solve_plan_on_line(GENTLE, RIDER)
    assert plan.converged
    assert np.max(np.abs(plan.n_m)) > 1.0  # it cuts the bend
    return plan


def _start(plan: Plan, s_m: float = START_M) -> Start:
    """A rider 1.5 kJ short of the plan's W' and 5 % slower, where the plan's line is."""
    return Start(s_m=s_m, state={"v": 0.95 * float(plan.at("v_mps", s_m)),
                                 "w_n": float(plan.at("w_n", s_m)),
                                 "e_n": float(plan.at("e_n", s_m)) - 1500.0 / RIDER.w_prime_j})


def test_offset_course_maps_both_ways(plan: Plan) -> None:
    n = np.interp(GENTLE.s_m, plan.s_m, plan.n_m)
    line = offset_course(GENTLE, n, "test line")
    assert line.length_ratio < 1.0  # inside of the bend: shorter
    s = np.array([0.0, 250.0, 700.0, GENTLE.length_m])
    assert line.road_s(line.line_s(s)) == pytest.approx(s, abs=1e-6)
    assert line.course.length_m == pytest.approx(line.s_line_m[-1], abs=1e-6)


def test_rest_on_the_plans_line_is_verified_on_the_road_and_warm(plan: Plan) -> None:
    line = offset_course(GENTLE, np.interp(GENTLE.s_m, plan.s_m, plan.n_m), "plan line")
    first, point = solve_rest_on_line(line, RIDER, Conditions(), OcpSettings(), guess=plan,
                                      start=_start(plan))
    assert first.converged and first.meta["success"], first.meta["attempts"]
    assert point is not None
    assert first.meta["line"]["kind"] == "plan" and on_line(first)
    # On the road's arc length from where the rider is, with the line's offset.
    assert first.s_m[0] == pytest.approx(START_M, abs=1e-6)
    assert first.s_m[-1] == pytest.approx(GENTLE.length_m, abs=1e-3)
    assert first.n_m == pytest.approx(np.interp(first.s_m, plan.s_m, plan.n_m), abs=0.05)
    assert first.meta["start"]["s_m"] == START_M
    assert first.w_prime_j[0] == pytest.approx(float(plan.at("w_prime_j", START_M)) - 1500.0,
                                               abs=1.0)
    # The rider is short of W' and slower: the rest takes longer than the plan's rest.
    assert first.finish_time_s > plan.finish_time_s - float(plan.at("t_s", START_M))
    fitted, why = line_corners(first, line, RIDER, Conditions())
    assert why == ""
    assert np.max(fitted.friction_use) <= 1.0
    # The next re-solve on the same line resumes from that point.
    again, _ = solve_rest_on_line(line, RIDER, Conditions(), OcpSettings(), guess=first,
                                  start=_start(first, 600.0), warm=point)
    assert again.converged
    assert again.meta["attempts"][0]["strategy"] == "warm"


def test_a_tight_corner_is_ridden_within_its_limits() -> None:
    """Round a 20 m bend the plain 1D on the line leaned far beyond C15 and C16 (helper
    B's refusals); the model that knows the corners brakes for it and passes."""
    tight = _bend(20.0)
    plan = solve_plan_on_line(tight, RIDER)
    line = offset_course(tight, np.interp(tight.s_m, plan.s_m, plan.n_m), "plan line")
    rest, _ = solve_rest_on_line(line, RIDER, Conditions(), OcpSettings(), guess=plan,
                                 start=_start(plan, 200.0))
    assert rest.meta["success"] and rest.model == "1dline"
    fitted, why = line_corners(rest, line, RIDER, Conditions())
    assert why == ""
    apex = np.argmax(np.abs(fitted.ay_mps2))
    assert abs(fitted.ay_mps2[apex]) > GRAVITY_MPS2 * np.tan(RIDER.pedal_lean_max_rad)
    assert rest.w_n[apex] <= 0.02  # no pedalling at that lean
    assert np.max(fitted.friction_use) <= 1.0 + 1e-3


def test_solve_rest_states_the_model(plan: Plan) -> None:
    n = np.interp(GENTLE.s_m, plan.s_m, plan.n_m)
    rest, point = solve_rest(RESOLVE_1D_LINE, GENTLE, RIDER, Conditions(), OcpSettings(),
                             plan, _start(plan), Warm(), n, (), LineCache())
    assert rest.converged and point is not None
    assert rest.meta["resolve"]["model"] == RESOLVE_1D_LINE


def test_a_failed_3d_resolve_falls_back_to_the_line(plan: Plan,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """Under 'auto' (a line given), a 3D re-solve that failed gives way to the 1D on the
    line, which says so; with the 3D alone (no line) the failed plan is returned."""
    def failed_3d(*_args: object, **_kwargs: object) -> tuple[Plan, None]:
        bad = dataclasses.replace(plan, solver_status="Maximum_CpuTime_Exceeded",
                                  meta={**plan.meta, "success": False})
        return bad, None

    monkeypatch.setattr(resolve_model, "solve_plan_point", failed_3d)
    n = np.interp(GENTLE.s_m, plan.s_m, plan.n_m)
    rest, point = solve_rest(RESOLVE_3D, GENTLE, RIDER, Conditions(), OcpSettings(),
                             plan, _start(plan), Warm(), n, (), LineCache())
    assert rest.converged and point is not None
    assert rest.meta["resolve"] == {
        "model": RESOLVE_1D_LINE, "line": rest.meta["resolve"]["line"],
        "after_3d_failed": "the 3D re-solve ended Maximum_CpuTime_Exceeded"}
    # The line refused too (its plan capped at one iteration): the failed 3D, saying why.
    both, _ = solve_rest(RESOLVE_3D, GENTLE, RIDER, Conditions(), OcpSettings(max_iter=1),
                         plan, _start(plan), Warm(), n, (), LineCache())
    assert both.solver_status == "Maximum_CpuTime_Exceeded"
    assert both.meta["resolve"]["line_refused"].startswith(
        "the 3D re-solve ended Maximum_CpuTime_Exceeded; the line's: ")
    alone, _ = solve_rest(RESOLVE_3D, GENTLE, RIDER, Conditions(), OcpSettings(),
                          plan, _start(plan), Warm(), None, (), LineCache())
    assert alone.solver_status == "Maximum_CpuTime_Exceeded"
    assert alone.meta["resolve"]["model"] == RESOLVE_3D


def test_worker_resolves_on_the_line(plan: Plan) -> None:
    rp = CourseReplanner(GENTLE, Conditions(), CourseReplanSettings(
        period_s=30.0, delay_s=15.0, min_remaining_m=200.0, model=RESOLVE_1D_LINE),
        deterministic=True, plan=plan)
    try:
        assert rp.request(100.0, RIDER, plan, _start(plan))
        assert rp.take(110.0) is None  # due 15 s of stamps after the request
        rest = rp.take(115.0)
        assert rest is not None and rest.converged
        assert rest.meta["resolve"]["model"] == RESOLVE_1D_LINE
        # The next re-solve rides the same line, warm from this one's point.
        assert rp.request(200.0, RIDER, rest, _start(rest, 700.0))
        assert rp.last_warm
        nxt = rp.take(215.0)
        assert nxt is not None and nxt.meta["resolve"]["model"] == RESOLVE_1D_LINE
        assert nxt.n_m == pytest.approx(np.interp(nxt.s_m, plan.s_m, plan.n_m), abs=0.05)
    finally:
        rp.close()


def _far_then_near(first: Plan) -> tuple[bool, Plan]:
    """`auto` (3D within 1 km of the finish, on this 1.4 km course) from the plan `first`:
    a re-solve 1.1 km from the finish, which must be the 1D on the line, then one from
    that plan 0.8 km from it. Returns whether the second was given a point of its model,
    and its plan."""
    rp = CourseReplanner(GENTLE, Conditions(), CourseReplanSettings(
        period_s=30.0, delay_s=15.0, min_remaining_m=200.0, model=RESOLVE_AUTO,
        auto_3d_max_m=1000.0), deterministic=True, plan=first)
    try:
        assert rp.request(100.0, RIDER, first, _start(first, 300.0))
        far = rp.take(115.0)
        assert far is not None and far.meta["resolve"]["model"] == RESOLVE_1D_LINE
        assert rp.request(200.0, RIDER, far, _start(far, 600.0))
        near = rp.take(215.0)
        assert near is not None
        return rp.last_warm, near
    finally:
        rp.close()


def test_auto_resolves_on_the_line_far_from_the_finish_and_3d_near_it(plan: Plan) -> None:
    """`auto`: the 1D on the line while more than `auto_3d_max_m` of the course is left,
    the 3D within it. From a 1D plan on the line there is no 3D point to start from: the
    3D ends Restoration_Failed from the line plan's primal point (442 iterations), so the
    plan is the line's, saying why."""
    warm, near = _far_then_near(plan)
    assert not warm
    assert (near.meta["resolve"]["model"] == RESOLVE_3D
            or near.meta["resolve"]["after_3d_failed"].startswith("the 3D re-solve"))


def test_a_3d_resolve_after_line_plans_starts_from_the_last_3d_plans_point() -> None:
    """`auto` from a 3D plan: the 3D re-solve after a 1D plan on the line starts from the
    first plan's point, not from the line plan's primal point alone
    (`resolve_model.Warm`), and converges without a restart (35 iterations; from the
    line plan's primal point: 85 to Restoration_Failed, then 44 with the smaller push)."""
    first = solve_keeping_point(GENTLE, RIDER, Conditions(), OcpSettings(), "3d")
    assert first.has_point
    warm, near = _far_then_near(first)
    assert warm
    assert near.meta["resolve"]["model"] == RESOLVE_3D and near.meta["success"]
    assert (near.meta["attempts"][0]["strategy"], near.meta["attempts"][0]["outcome"]) == (
        "warm", "converged")


def test_settings_reject_an_unknown_model() -> None:
    with pytest.raises(ValueError, match="re-solve model"):
        CourseReplanSettings(model="2d")


def test_plan_in_force_counts_the_model(plan: Plan, monkeypatch: pytest.MonkeyPatch) -> None:
    n = np.interp(GENTLE.s_m, plan.s_m, plan.n_m)
    rest, _ = solve_rest(RESOLVE_1D_LINE, GENTLE, RIDER, Conditions(), OcpSettings(),
                         plan, _start(plan), Warm(), n, (), LineCache())
    stats: Counter[str] = Counter()
    plans = PlanInForce(GENTLE, plan, RIDER.critical_power_w, band_j=2000.0,
                        conditions=Conditions(), replan=CourseReplanSettings(period_s=0.0),
                        deterministic=True, stats=stats)
    try:
        monkeypatch.setattr(plans._replanner, "take", lambda _stamp_s: rest)  # a done re-solve
        assert plans.take(100.0)
        assert plans.plan is rest and plans.version == 1
        assert stats["course_replans_model_1d-line"] == 1
        assert stats["course_replans_line_refused"] == 0
        assert plans.adopted == [{"s_m": START_M, "model": RESOLVE_1D_LINE,
                                  "rest_s": rest.finish_time_s, "iterations": rest.iterations,
                                  "solve_time_s": rest.solve_time_s}]
    finally:
        plans.close()
