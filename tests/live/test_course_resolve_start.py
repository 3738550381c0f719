"""The start of a re-solve of the rest of the course (`course_replan.start_from`) is one
the full-course OCP can represent: a rider stopped in a corner, or slower than the plan
where the plan leans into a corner on the inside edge, gets a converged and verified
plan (issue 14: on the Zwift Bologna ride such re-solves ended Infeasible_Problem_Detected).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from support.courses import hairpin

from itt_planner.live.course_replan import UNMEASURED_STATES, free_states, start_from
from itt_planner.model.conditions import GRAVITY_MPS2
from itt_planner.model.rider import PRESETS
from itt_planner.model.state import RiderState
from itt_planner.ocp.course_nlp import start_speed
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.course_settings import OcpSettings
from itt_planner.ocp.horizon import HorizonPlanner
from itt_planner.ocp.horizon_settings import HorizonSettings
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import PlanStatus

COURSE = hairpin(straight_m=120.0)
RIDER = PRESETS["paper"]


@pytest.fixture(scope="module")
def plan() -> Plan:
    plan = solve_plan(COURSE, RIDER, model="3d")
    assert plan.converged, plan.meta["attempts"]
    return plan


@pytest.fixture(scope="module")
def planner(plan: Plan) -> HorizonPlanner:
    return HorizonPlanner(COURSE, RIDER, plan, settings=HorizonSettings(horizon_m=100.0))


def in_the_corner(plan: Plan, speed_factor: float) -> tuple[float, RiderState]:
    """Where the plan leans most in the hairpin, a rider at `speed_factor` of its speed."""
    k = int(abs(plan.phi_rad).argmax())
    s = float(plan.s_m[k])
    t = float(plan.t_s[k])
    return s, RiderState(stamp_s=t, s_m=s, n_m=float(plan.n_m[k]),
                         speed_mps=speed_factor * float(plan.v_mps[k]),
                         heading_rad=float(COURSE.at("theta_rad", s) + plan.alpha_rad[k]),
                         power_w=0.0, w_prime_j=float(plan.w_prime_j[k]), elapsed_s=t)


def resolve(plan: Plan, planner: HorizonPlanner, s_m: float, state: RiderState) -> Plan:
    """The worker's solve (`resolve_worker.worker_main`), in this process."""
    start = start_from(planner, state, s_m)
    launch = start_speed(RIDER, planner.conditions, OcpSettings())
    return solve_plan(COURSE, RIDER, model="3d", guess=plan, start=start,
                      free_start=free_states(start, launch))


def test_stopped_rider_starts_as_at_the_start_line(plan: Plan, planner: HorizonPlanner) -> None:
    """Stopped at the apex, where the plan leans most: the re-solve launches at the OCP's
    start speed with critical power, upright, and converges to a verified plan."""
    s, moving = in_the_corner(plan, 1.0)
    assert abs(float(plan.at("phi_rad", s))) > 0.3  # a lean no rider at 1 m/s can hold
    stopped = dataclasses.replace(moving, speed_mps=0.0)
    start = start_from(planner, stopped, s)
    launch = start_speed(RIDER, planner.conditions, OcpSettings())
    assert start.state["v"] == launch
    assert start.state["w_n"] * RIDER.max_power_w == pytest.approx(RIDER.critical_power_w)
    assert start.state["phi"] == 0.0 and start.state["phi_dot"] == 0.0
    rest = resolve(plan, planner, s, stopped)
    assert rest.status == PlanStatus.CONVERGED, rest.meta["attempts"]
    assert rest.meta["success"] and rest.meta["verification"]["verified"]
    assert rest.v_mps[0] == pytest.approx(launch)
    assert rest.phi_rad[0] == 0.0 and rest.phi_dot_radps[0] == 0.0  # upright and still
    assert rest.meta["start"]["free"] == ["delta_n"]


def test_slow_rider_in_a_corner(plan: Plan, planner: HorizonPlanner) -> None:
    """70 % of the plan's speed where the plan leans most: the plan's lean does not fit
    the rider's speed, so the re-solve chooses lean and steering (`UNMEASURED_STATES`)
    and keeps the measured speed and W'."""
    s, slow = in_the_corner(plan, 0.7)
    rest = resolve(plan, planner, s, slow)
    assert rest.status == PlanStatus.CONVERGED, rest.meta["attempts"]
    assert rest.meta["verification"]["verified"]
    assert rest.v_mps[0] == pytest.approx(slow.speed_mps, rel=1e-6)
    assert rest.w_prime_j[0] == pytest.approx(slow.w_prime_j, rel=1e-6)
    assert rest.meta["start"]["free"] == list(UNMEASURED_STATES)


def test_slow_rider_leans_into_the_corner(plan: Plan, planner: HorizonPlanner) -> None:
    """The slow rider of `test_slow_rider_in_a_corner`: the lean the re-solve starts
    with is into the turn, no more than the plan's (which balances a faster rider) and
    at least the steady lean of the rider's speed on the centre line (E5; the plan's
    line is wider, so a little less would do: a tenth of margin)."""
    s, slow = in_the_corner(plan, 0.7)
    rest = resolve(plan, planner, s, slow)
    assert rest.status == PlanStatus.CONVERGED, rest.meta["attempts"]
    plan_lean = float(plan.at("phi_rad", s))
    steady = -np.arctan(slow.speed_mps ** 2 * float(COURSE.at("kappa_per_m", s)) / GRAVITY_MPS2)
    assert np.sign(rest.phi_rad[0]) == np.sign(plan_lean) == np.sign(steady)
    assert 0.9 * abs(steady) < abs(rest.phi_rad[0]) < abs(plan_lean)
