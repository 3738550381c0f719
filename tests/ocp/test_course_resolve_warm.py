"""A re-solve of the rest of the course from a previous plan's primal-dual point
(`solve_plan(warm=)`): on that plan's mesh cut at the start, converged and verified, and
back to the usual restarts where the start needs a finer mesh (issue 14: on the Zwift
Bologna ride such re-solves took 8-10 iterations instead of 46-116 from the primal point)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from support.courses import hairpin

from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import PRESETS
from itt_planner.ocp import course_nlp as course_nlp_module
from itt_planner.ocp.course_nlp import CourseNlp, PrimalDual, course_nlp
from itt_planner.ocp.course_problem import solve_plan_point
from itt_planner.ocp.course_settings import OcpSettings, Start
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import PlanStatus

COURSE = hairpin(straight_m=120.0)
RIDER = PRESETS["paper"]
#: The lean and the steering left to the solver (what a rider's estimate does not
#: measure); the roll rate stays the plan's. Free, the roll rate is a free lunch: from
#: the plan's own state in the hairpin the solver started the rider leaning 1.1 rad out
#: of the turn, rolling back, and "beat" the plan's rest by 0.5 s of 11.3 s; before the
#: hairpin it left the plan's optimum (a saddle once the roll rate is free) and took 76
#: iterations, ending on another local optimum with some guesses (+0.08 s).
FREE = ("phi", "delta_n")


@pytest.fixture(scope="module")
def solved() -> tuple[Plan, PrimalDual]:
    plan, point = solve_plan_point(COURSE, RIDER, model="3d")
    assert plan.converged, plan.meta["attempts"]
    assert point is not None and len(point.nodes) == plan.n_nodes
    return plan, point


def plan_state(plan: Plan, k: int, **change: float) -> Start:
    names = {"n": "n_m", "alpha": "alpha_rad", "phi": "phi_rad", "phi_dot": "phi_dot_radps",
             "v": "v_mps", "w_n": "w_n", "delta_n": "delta_n", "e_n": "e_n"}
    state = {name: float(getattr(plan, array)[k]) for name, array in names.items()}
    return Start(s_m=float(plan.s_m[k]), state=state | change)


def test_from_the_plans_own_state_it_is_the_plan(solved: tuple[Plan, PrimalDual]) -> None:
    """Bellman: from the plan's own state at one of its nodes, the rest of the plan is
    the optimum (the lean and steering free at the plan's values); the warm run converges
    on the plan's own nodes, to the plan's rest, before the hairpin and in it."""
    plan, point = solved
    for k in (plan.n_nodes // 3, int(abs(plan.phi_rad).argmax())):
        rest = solve_plan_point(COURSE, RIDER, model="3d", guess=plan,
                                start=plan_state(plan, k), free_start=FREE, warm=point)[0]
        assert rest.status == PlanStatus.CONVERGED, rest.meta["attempts"]
        assert rest.meta["attempts"][0]["strategy"] == "warm"
        np.testing.assert_allclose(rest.s_m, plan.s_m[k:])
        rest_s = plan.finish_time_s - plan.t_s[k]
        assert rest.finish_time_s == pytest.approx(rest_s, abs=0.01)
        np.testing.assert_allclose(rest.v_mps, plan.v_mps[k:], atol=0.3)


def test_off_the_plan_warm_and_verified(solved: tuple[Plan, PrimalDual]) -> None:
    """10 % slower and 2 kJ short before the hairpin: a converged, verified plan from the
    warm start that starts at the rider's speed and W'; the next re-solve can start from
    its point."""
    plan, point = solved
    k = int(np.searchsorted(plan.s_m, 60.0))
    start = plan_state(plan, k, v=0.9 * float(plan.v_mps[k]),
                       e_n=float(plan.e_n[k]) - 2000.0 / RIDER.w_prime_j)
    rest, again = solve_plan_point(COURSE, RIDER, model="3d", guess=plan, start=start,
                                   free_start=FREE, warm=point)
    assert rest.status == PlanStatus.CONVERGED, rest.meta["attempts"]
    assert rest.meta["attempts"][0]["strategy"] == "warm"
    assert rest.meta["verification"]["verified"]
    assert rest.v_mps[0] == pytest.approx(start.state["v"], rel=1e-6)
    assert rest.e_n[0] == pytest.approx(start.state["e_n"], rel=1e-6)
    assert again is not None and len(again.nodes) == rest.n_nodes


def test_a_slow_start_splits_the_plans_intervals(solved: tuple[Plan, PrimalDual]) -> None:
    """At 2 m/s where the plan rides 10 m/s, the plan's 4 m intervals are too long for
    the launch (`mesh.speed_spacing_m`): the warm run's mesh splits them where the rider
    is slow, and keeps the plan's own nodes; converged and verified."""
    plan, point = solved
    k = int(np.searchsorted(plan.s_m, 30.0))
    start = plan_state(plan, k, v=2.0)
    rest = solve_plan_point(COURSE, RIDER, model="3d", guess=plan, start=start,
                            free_start=FREE, warm=point)[0]
    assert rest.status == PlanStatus.CONVERGED, rest.meta["attempts"]
    assert rest.meta["attempts"][0]["strategy"] == "warm"
    assert rest.meta["verification"]["verified"]
    assert np.diff(rest.s_m)[0] < np.diff(plan.s_m)[k]  # split at the launch
    assert set(plan.s_m[k + 1:]) <= set(rest.s_m)  # the plan's own nodes stay


def test_a_failed_warm_run_restarts_on_a_mesh_of_its_own(
        solved: tuple[Plan, PrimalDual]) -> None:
    """Standing (1 m/s, upright) 60 m before the hairpin: the warm run on the split plan
    mesh stops at its share; the restarts on the mesh built for the start converge."""
    plan, point = solved
    k = int(np.searchsorted(plan.s_m, 60.0))
    start = plan_state(plan, k, v=1.0, phi=0.0, phi_dot=0.0)
    rest = solve_plan_point(COURSE, RIDER, model="3d", guess=plan, start=start,
                            free_start=("delta_n",), warm=point)[0]
    assert rest.status == PlanStatus.CONVERGED, rest.meta["attempts"]
    assert rest.meta["verification"]["verified"]


def test_a_resolve_from_a_plan_of_its_model_builds_no_default_guess(
        solved: tuple[Plan, PrimalDual], monkeypatch: pytest.MonkeyPatch) -> None:
    """The plan and the rider's start give every row of a 3D re-solve's guess: the NLP is
    the one built over the default guess (which it would overwrite whole), without
    building that guess (a fifth of a warm 3D re-solve's time on the Zwift Bologna ride)."""
    plan, point = solved
    start = plan_state(plan, plan.n_nodes // 2, v=0.9 * float(plan.v_mps[plan.n_nodes // 2]))
    nodes = point.nodes[point.nodes >= start.s_m]
    v0 = start.state["v"]

    def build() -> CourseNlp:
        return course_nlp(COURSE, RIDER, Conditions(), OcpSettings(), "3d", nodes, v0, start,
                          plan, FREE)

    before = build()
    monkeypatch.setattr(course_nlp_module, "initial_guess", _no_default_guess)
    after = build()
    for name in ("p", "lbw", "ubw", "x_guess", "u_guess"):
        np.testing.assert_array_equal(getattr(after, name), getattr(before, name), name)
    # A 1D plan has no lateral rows: the default guess is built for them.
    plan_1d = dataclasses.replace(plan, model="1d")
    with pytest.raises(AssertionError, match="default guess"):
        course_nlp(COURSE, RIDER, Conditions(), OcpSettings(), "3d", nodes, v0, start,
                   plan_1d, FREE)


def _no_default_guess(*_: object) -> tuple[np.ndarray, np.ndarray]:
    raise AssertionError("the default guess was built")
