"""Every plan is checked by an independent replay (issue 18): sound plans pass, a plan
replayed off its model or riding on an integration artefact is `invalid`."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from itt_planner.course.builder import build_course
from itt_planner.model.conditions import Conditions
from itt_planner.model.dynamics import build_1d
from itt_planner.model.params import ModelParams
from itt_planner.model.rider import Rider
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.course_settings import OcpSettings
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import PlanStatus
from itt_planner.ocp.transcription import transcribe
from itt_planner.ocp.verify import verify_plan

#: The rider of issue 18.
RIDER = Rider(name="issue18", mass_kg=86.0, drag_area_m2=0.273, critical_power_w=290.0)
#: The issue's 4 km flat loop, twice (a course-builder twin: 4 corners of 20 m per lap).
LOOP = build_course({"name": "flat-loop-2laps", "segments": [
    seg for _ in range(8) for seg in (
        {"type": "straight", "length_m": 900 if _ % 2 == 0 else 1037},
        {"type": "arc", "angle_deg": 90, "radius_m": 20, "direction": "left"})]})
HILL = build_course({"name": "hill", "segments": [
    {"type": "straight", "length_m": 300, "grade_pct": 1},
    {"type": "straight", "length_m": 700, "grade_pct": 7},
    {"type": "straight", "length_m": 900, "grade_pct": -9},
    {"type": "straight", "length_m": 300}]})


@pytest.fixture(scope="module")
def hill_plan() -> Plan:
    return solve_plan(HILL, RIDER, model="1d")


def test_a_converged_plan_is_verified_and_says_so(hill_plan: Plan) -> None:
    assert hill_plan.status == PlanStatus.CONVERGED.value and hill_plan.converged
    ver = hill_plan.meta["verification"]
    assert ver["verified"] is True
    # The replay agrees far inside the tolerance: a few cm/s, a few hundredths of a s.
    assert ver["max_speed_error_mps"] < 0.05
    assert abs(ver["finish_time_error_s"]) < 0.1
    assert ver["max_w_prime_error_j"] < 50.0


def test_the_issue_loop_with_2000_iterations_is_converged_and_verified() -> None:
    """The issue's case (2 laps of a 4 km loop, --max-iter 2000): it came out as a
    618 s 'Solve_Succeeded' that rested at 0.5 m/s and coasted at 250 m/s."""
    plan = solve_plan(LOOP, RIDER, settings=OcpSettings(max_iter=2000), model="1d")
    assert plan.converged, plan.meta["attempts"]
    assert plan.meta["verification"]["verified"]
    assert plan.v_mps.max() < 20.0  # 290 W on the flat: ~41 km/h, not 900
    assert plan.v_mps[plan.s_m > 100].min() > 5.0  # no rest stop
    assert 650 < plan.finish_time_s < 720


def test_a_perturbed_power_trace_is_flagged(hill_plan: Plan) -> None:
    """Controls replayed off the model: 15 % more power over the climb than the plan's
    speeds were integrated with."""
    climb = (hill_plan.s_m > 300) & (hill_plan.s_m < 1000)
    w_n = np.where(climb, hill_plan.w_n * 1.15, hill_plan.w_n)
    ver = verify_plan(dataclasses.replace(hill_plan, w_n=w_n), HILL, RIDER)
    assert not ver.verified
    assert ver.worst in ("speed", "time", "w_prime")
    assert 300 <= ver.worst_s_m <= HILL.length_m


def test_a_non_finite_command_fails_as_a_non_finite_replay(hill_plan: Plan) -> None:
    """A NaN in the plan's command is not replayed as 0 W (CasADi's fmax(NaN, 0) is 0):
    the replay is non-finite and the plan refused, without an exception."""
    w_n = hill_plan.w_n.copy()
    w_n[len(w_n) // 2] = np.nan
    ver = verify_plan(dataclasses.replace(hill_plan, w_n=w_n), HILL, RIDER)
    assert not ver.verified and ver.worst == "non-finite replay"


def test_rest_and_sprint_is_flagged_and_infeasible(hill_plan: Plan) -> None:
    """The issue's artefact: brake to 0.5 m/s, then 0.5 -> 258 m/s within one 10 m
    interval. The replay finds the plan's speed impossible, and the transcription's
    acceleration bound makes such a step infeasible for the NLP."""
    s = hill_plan.s_m
    k = int(np.searchsorted(s, 1950.0))
    v = hill_plan.v_mps.copy()
    v[k - 3: k + 1] = 0.5
    v[k + 1:] = 258.0
    t = hill_plan.t_s.copy()
    t[k + 1:] = t[k] + (s[k + 1:] - s[k]) / 258.0
    fake = dataclasses.replace(hill_plan, v_mps=v, t_s=t, w_n=np.where(s >= s[k - 1], 1.0,
                                                                      hill_plan.w_n))
    ver = verify_plan(fake, HILL, RIDER)
    assert not ver.verified and ver.worst == "speed" and ver.max_speed_error_mps > 100

    tr = transcribe(build_1d(), 1, compile_c=False)
    par = ModelParams(RIDER, Conditions()).vector()
    road = np.array([[0.0], [0.0], [0.0], [10.0]])
    w = tr.layout.join(np.array([[0.5, 258.0], [1.0, 1.0], [1.0, 0.9]]), np.zeros((1, 1)))
    import casadi as ca

    g = np.asarray(ca.Function("g", [tr.nlp["x"], tr.nlp["p"]], [tr.nlp["g"]])(
        w, tr.params(road, par))).ravel()
    assert g[tr.layout.accel_rows][0] > 1000  # m/s^2 beyond tyres + gravity


def test_speed_bound_keeps_plans_physical(hill_plan: Plan) -> None:
    """v_max from physics: far above any speed of the plan, far below the artefact."""
    from itt_planner.model.steady import speed_bound_mps

    bound = speed_bound_mps(RIDER, Conditions(), float(np.tan(HILL.beta_rad.min())))
    assert hill_plan.v_mps.max() < 0.8 * bound < 50.0


def test_3d_plan_lateral_check() -> None:
    """3D: the per-interval re-integration of the roll/steer dynamics agrees; a steering
    trace replayed off the plan does not."""
    course = build_course({"name": "bend", "segments": [
        {"type": "straight", "length_m": 150},
        {"type": "clothoid", "length_m": 10, "radius_m": 25, "direction": "right"},
        {"type": "arc", "angle_deg": 70, "radius_m": 25, "direction": "right"},
        {"type": "clothoid", "length_m": 10},
        {"type": "straight", "length_m": 150}]})
    plan = solve_plan(course, RIDER, model="3d")
    assert plan.converged, plan.meta["attempts"]
    ver = plan.meta["verification"]
    assert ver["verified"] and ver["max_roll_defect_rad"] < 0.02
    from itt_planner.model.wprime import WPrimeModel
    from itt_planner.ocp.course_nlp import spatial_model

    bad = dataclasses.replace(plan, u_delta=plan.u_delta + 2.0)
    again = verify_plan(bad, course, RIDER, model=spatial_model("3d", WPrimeModel.SKIBA))
    assert not again.verified and again.worst in ("lateral", "heading", "roll")
    # The intervals it does not resolve are named by their start, for the restarts to
    # split them (the worst defect is placed at its interval's end).
    worst_end = int(np.searchsorted(plan.s_m, again.worst_s_m))
    assert plan.s_m[worst_end - 1] in again.unresolved_s_m
    assert set(again.unresolved_s_m) <= set(plan.s_m[:-1])
    assert again.as_dict()["unresolved_intervals"] == len(again.unresolved_s_m)
    assert ver["unresolved_intervals"] == 0


def test_a_3d_plan_with_unresolved_intervals_is_resolved_on_them_split(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A 3D plan whose check finds an interval the step does not resolve (here made up:
    the first check names the longest interval) is re-solved on its nodes with that
    interval split, resumed from its point, and verified (`CourseSolve.refine`)."""
    from itt_planner.ocp import course_restarts

    real = verify_plan
    flagged: list[tuple[float, float]] = []  # the interval named: its start and end

    def flag_once(plan: Plan, *args: object, **kwargs: object) -> object:
        check = real(plan, *args, **kwargs)  # type: ignore[arg-type]
        if flagged:
            return check
        i = int(np.argmax(np.diff(plan.s_m)))
        flagged.append((float(plan.s_m[i]), float(plan.s_m[i + 1])))
        return dataclasses.replace(check, verified=False, unresolved_s_m=(flagged[0][0],))

    monkeypatch.setattr(course_restarts, "verify_plan", flag_once)
    plan = solve_plan(HILL, RIDER, model="3d")
    first, refined = plan.meta["attempts"][0], plan.meta["attempts"][-1]
    assert plan.converged and refined["strategy"] == "refined where slow, resumed"
    assert refined["n_nodes"] > first["n_nodes"]
    (a, b), = flagged
    inside = plan.s_m[(plan.s_m > a) & (plan.s_m < b)]
    assert inside == pytest.approx([0.5 * (a + b)])  # the interval split in two
