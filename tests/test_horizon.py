"""Receding-horizon OCP: replans along a hairpin course, W' >= 0, warm starts, failures."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from itt_planner.horizon import HorizonPlanner, HorizonSettings, HorizonSolution
from itt_planner.ocp import solve_plan
from itt_planner.plan import Plan
from itt_planner.rider import PRESETS
from itt_planner.state import RiderState
from tests.test_ocp import hairpin

COURSE = hairpin(straight_m=600.0)


@pytest.fixture(scope="module")
def plan() -> Plan:
    return solve_plan(COURSE, PRESETS["paper"], model="3d")


@pytest.fixture(scope="module")
def planner(plan: Plan) -> HorizonPlanner:
    # A generous wall-time cap: on a loaded CI machine outcomes must depend on iterations only.
    return HorizonPlanner(COURSE, PRESETS["paper"], plan,
                          settings=HorizonSettings(horizon_m=500.0, max_wall_time_s=20.0))


def plan_state(plan: Plan, s: float) -> RiderState:
    return RiderState(
        stamp_s=float(plan.at("t_s", s)), s_m=s, n_m=float(plan.at("n_m", s)),
        speed_mps=float(plan.at("v_mps", s)),
        heading_rad=float(COURSE.at("theta_rad", s) + plan.at("alpha_rad", s)),
        power_w=float(plan.at("power_w", s)), w_prime_j=float(plan.at("w_prime_j", s)),
        elapsed_s=float(plan.at("t_s", s)))


def test_replans_along_a_hairpin(plan: Plan, planner: HorizonPlanner) -> None:
    planner.reset()
    sols = [planner.solve(plan_state(plan, s)) for s in np.arange(0.0, COURSE.length_m - 20, 60.0)]
    assert sum(s.success for s in sols) >= len(sols) - 1, [s.status for s in sols]
    for sol in sols:
        assert isinstance(sol, HorizonSolution)
        if sol.success:
            assert sol.w_prime_j.min() >= -0.01
            assert np.all(np.diff(sol.t_s) > 0)
            # Riding the plan's own states predicts the plan's finish.
            assert sol.predicted_finish_s == pytest.approx(plan.finish_time_s, rel=0.02)


def test_warm_start_from_previous_solution(plan: Plan, planner: HorizonPlanner) -> None:
    """Re-solving the same window from the previous solution is (nearly) free."""
    planner.reset()
    cold = planner.solve(plan_state(plan, 100.0))
    warm = planner.solve(plan_state(plan, 100.0))
    assert cold.success and warm.success
    assert warm.iterations < cold.iterations


def test_warm_start_beats_cold_on_shifted_windows(plan: Plan, planner: HorizonPlanner) -> None:
    """A sequence of windows shifted by ~one replan period: warm needs fewer iterations."""
    positions = np.arange(100.0, 500.0, 20.0)
    planner.reset()
    warm = [planner.solve(plan_state(plan, s)) for s in positions]
    cold = []
    for s in positions:
        planner.reset()
        cold.append(planner.solve(plan_state(plan, s)))
    assert all(w.success for w in warm), [w.status for w in warm]
    assert sum(w.iterations for w in warm[1:]) < sum(c.iterations for c in cold[1:])


def test_off_plan_state_keeps_w_prime_non_negative(plan: Plan) -> None:
    # A cold start with W' nearly empty while surging needs ~120-140 iterations
    # (bench/results_horizon.md): this test gives it the iterations, not the default cap.
    deep = HorizonPlanner(COURSE, PRESETS["paper"], plan,
                          settings=HorizonSettings(horizon_m=500.0, max_iter=300,
                                                   max_wall_time_s=20.0))
    low = dataclasses.replace(plan_state(plan, 200.0), w_prime_j=300.0, power_w=900.0)
    sol = deep.solve(low)
    assert sol.success, sol.status
    assert sol.w_prime_j.min() >= -0.01


def test_failure_returns_status_not_exception(plan: Plan) -> None:
    tight = HorizonPlanner(COURSE, PRESETS["paper"], plan,
                           settings=HorizonSettings(horizon_m=500.0, max_iter=1))
    bad = dataclasses.replace(plan_state(plan, 550.0), speed_mps=25.0, n_m=-3.0, power_w=1800.0)
    sol = tight.solve(bad)
    assert not sol.success
    assert sol.status
    garbage = dataclasses.replace(plan_state(plan, 10.0), speed_mps=float("nan"),
                                  power_w=float("nan"))
    assert isinstance(tight.solve(garbage), HorizonSolution)
