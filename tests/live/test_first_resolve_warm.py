"""The first re-solve of the rest of the course starts warm from the primal-dual point
the plan in force carries (`plan.POINT_ARRAYS`, kept by the plan cache and in plan files:
`live.course_replan.plan_point`), and the engine's counters say which way each re-solve
started; a plan without a usable point (an older file, a 1D plan, a point of another
mesh) starts as before, from its primal point, and says so."""

from __future__ import annotations

import dataclasses
from collections import Counter

import numpy as np
import pytest
from support.courses import hairpin

from itt_planner.live.course_replan import CourseReplanSettings, plan_point
from itt_planner.live.plan_in_force import PlanInForce
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import PRESETS
from itt_planner.model.state import RiderState
from itt_planner.ocp.cache import with_point
from itt_planner.ocp.course_problem import solve_plan_point
from itt_planner.ocp.course_settings import OcpSettings
from itt_planner.ocp.horizon import HorizonPlanner
from itt_planner.ocp.horizon_settings import HorizonSettings
from itt_planner.ocp.plan import Plan

COURSE = hairpin(straight_m=300.0)
RIDER = PRESETS["paper"]
S_OFF_M = 150.0


@pytest.fixture(scope="module")
def plan() -> Plan:
    """The 3D plan keeping its point, as the plan cache stores it."""
    plan = with_point(*solve_plan_point(COURSE, RIDER, model="3d"))
    assert plan.converged and plan.has_point, plan.meta["attempts"]
    return plan


def off_plan_state(plan: Plan) -> RiderState:
    """Before the hairpin, 4 kJ of W' short and 10 % slow."""
    s, t = S_OFF_M, float(plan.at("t_s", S_OFF_M))
    return RiderState(stamp_s=t, s_m=s, n_m=float(plan.at("n_m", s)),
                      speed_mps=0.9 * float(plan.at("v_mps", s)),
                      heading_rad=float(COURSE.at("theta_rad", s) + plan.at("alpha_rad", s)),
                      power_w=float(plan.at("power_w", s)),
                      w_prime_j=float(plan.at("w_prime_j", s)) - 4000.0, elapsed_s=t)


def _without_point(plan: Plan) -> Plan:
    """`plan` as a file from before the point was kept loads."""
    return dataclasses.replace(plan, point_w=None, point_lam_x=None, point_lam_g=None)


def test_plan_point_is_the_plans_own_or_none(plan: Plan) -> None:
    settings = OcpSettings()
    point, why = plan_point(plan, settings)
    assert point is not None and why == ""
    assert point.nodes is plan.s_m and point.w is plan.point_w
    bare = _without_point(plan)
    assert plan_point(bare, settings) == (None, "the plan carries no primal-dual point")
    as_1d = dataclasses.replace(plan, model="1d")
    assert plan_point(as_1d, settings)[0] is None
    assert "1d" in plan_point(as_1d, settings)[1]
    assert plan.point_w is not None
    short = dataclasses.replace(plan, point_w=plan.point_w[:-1])
    assert plan_point(short, settings)[0] is None  # not the NLP on the plan's nodes
    assert "sizes" in plan_point(short, settings)[1]


def _first_resolve(plan: Plan) -> tuple[Plan, Counter[str]]:
    """The first re-solve of the rest of the course, asked and taken as the engine does."""
    stats: Counter[str] = Counter()
    planner = HorizonPlanner(COURSE, RIDER, plan, settings=HorizonSettings(horizon_m=300.0))
    plans = PlanInForce(COURSE, plan, RIDER.critical_power_w, band_j=2000.0,
                        conditions=Conditions(), replan=CourseReplanSettings(
                            period_s=30.0, delay_s=15.0, min_remaining_m=200.0),
                        deterministic=True, stats=stats)
    try:
        state = off_plan_state(plan)
        plans.request(state.stamp_s, planner, state)
        assert stats["course_replans_asked"] == 1
        assert plans.take(state.stamp_s + 15.0)
        return plans.plan, stats
    finally:
        plans.close()


def test_first_resolve_starts_warm_from_the_plans_point(plan: Plan) -> None:
    """With the point: the first re-solve resumes from it ("warm", converged at once, in
    fewer iterations than from the primal point) and is counted warm; without it (an
    older file): from the primal point, counted cold. Both plans converge and verify,
    and ride the rest of the course alike."""
    warm, warm_stats = _first_resolve(plan)
    cold, cold_stats = _first_resolve(_without_point(plan))
    assert warm_stats["course_replans_started_warm"] == 1
    assert warm_stats["course_replans_warm_converged"] == 1
    assert "course_replans_started_cold" not in warm_stats
    assert cold_stats["course_replans_started_cold"] == 1
    assert "course_replans_started_warm" not in cold_stats
    assert "course_replans_warm_converged" not in cold_stats
    assert warm.meta["attempts"][0]["strategy"] == "warm"
    assert cold.meta["attempts"][0]["strategy"] == "guess"
    for rest in (warm, cold):
        assert rest.converged and rest.meta["success"], rest.meta["attempts"]
        assert rest.s_m[0] == pytest.approx(S_OFF_M)
    assert warm.iterations < cold.iterations
    assert warm.finish_time_s == pytest.approx(cold.finish_time_s, rel=5e-3)
    assert np.all(np.isfinite(warm.power_w))
