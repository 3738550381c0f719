"""A plan its verification refuses is solved again, never used and never re-solved from
itself: a warm re-solve of the rest of the course that converged onto an artefact of the
old plan's mesh starts again from the guess on a mesh built for the start
(`course_restarts.CourseSolve.warm`), and a 1D plan on a line ("1dline") is refined like
the 1D, from the guess (`course_refine`). A Sauerland re-solve on the line converged warm
onto a jump from 2 to 14 m/s in one 10 m interval, and its refinement from itself rode the
same jump (bench/RESULTS.md, 2026-12-03, lead, third session).

The refusal is forced here (the first verification fails) so that each restart runs on a
small course in seconds; the plans after it are verified for real."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest

from itt_planner.course.builder import build_course
from itt_planner.course.geometry import Course
from itt_planner.model.rider import PRESETS
from itt_planner.ocp import course_restarts
from itt_planner.ocp.course_problem import solve_plan, solve_plan_point
from itt_planner.ocp.course_restarts import CourseSolve
from itt_planner.ocp.course_settings import Start
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import PlanStatus
from itt_planner.ocp.verify import Verification, verify_plan

RIDER = PRESETS["paper"]


@pytest.fixture(scope="module")
def bend() -> Course:
    """300 m downhill at -4 % into a 90-degree left bend of 15 m, 300 m level after."""
    return build_course({"name": "tight-bend", "segments": [
        {"type": "straight", "length_m": 300.0, "grade_pct": -4.0},
        {"type": "arc", "angle_deg": 90, "radius_m": 15.0, "direction": "left"},
        {"type": "straight", "length_m": 300.0, "grade_pct": 0.0}]})


def refuse_first_check(monkeypatch: pytest.MonkeyPatch) -> list[Verification]:
    """From now on the first verification fails (speed 16x its tolerance, as on
    Sauerland); the checks made, in order."""
    checks: list[Verification] = []
    real = verify_plan  # what `course_restarts` calls

    def check(*args: Any, **kwargs: Any) -> Verification:
        checks.append(real(*args, **kwargs))
        if len(checks) == 1:
            return dataclasses.replace(checks[0], verified=False, worst="speed",
                                       worst_ratio=16.0)
        return checks[-1]

    monkeypatch.setattr(course_restarts, "verify_plan", check)
    return checks


def guesses_of_nlps(monkeypatch: pytest.MonkeyPatch) -> list[Plan | None]:
    """The guess of every NLP a `CourseSolve` builds from now on."""
    guesses: list[Plan | None] = []
    real = CourseSolve.nlp

    def nlp(self: CourseSolve, nodes: Any, guess: Plan | None) -> Any:
        guesses.append(guess)
        return real(self, nodes, guess)

    monkeypatch.setattr(CourseSolve, "nlp", nlp)
    return guesses


def test_a_refused_warm_plan_starts_again_from_the_guess(
        bend: Course, monkeypatch: pytest.MonkeyPatch) -> None:
    """The warm run converges, its plan is refused: the next run starts from the plan in
    force on a mesh built for the start, and that plan, verified, is the result."""
    plan, point = solve_plan_point(bend, RIDER, model="1d")
    assert plan.meta["success"] and point is not None
    k = plan.n_nodes // 3
    start = Start(s_m=float(plan.s_m[k]), state={
        "v": 0.9 * float(plan.v_mps[k]), "w_n": float(plan.w_n[k]), "e_n": float(plan.e_n[k])})
    checks = refuse_first_check(monkeypatch)
    guesses = guesses_of_nlps(monkeypatch)
    rest = solve_plan_point(bend, RIDER, model="1d", guess=plan, start=start, warm=point)[0]
    attempts = rest.meta["attempts"]
    assert [a["strategy"] for a in attempts[:2]] == ["warm", "guess"], attempts
    assert attempts[0]["outcome"] == "converged"
    assert len(checks) == 2 and guesses[-1] is plan
    assert rest.status == PlanStatus.CONVERGED.value and rest.meta["verification"]["verified"]
    assert rest.v_mps[0] == pytest.approx(start.state["v"])


def test_a_refused_line_plan_is_refined_from_the_guess(
        bend: Course, monkeypatch: pytest.MonkeyPatch) -> None:
    """A "1dline" plan refused: re-solved from the solve's guess (none here: the default
    one) on a mesh built afresh, never from the refused plan; the result is verified."""
    checks = refuse_first_check(monkeypatch)
    guesses = guesses_of_nlps(monkeypatch)
    plan = solve_plan(bend, RIDER, model="1dline")
    strategies = [a["strategy"] for a in plan.meta["attempts"]]
    assert strategies[-1] in ("refined where slow", "finer mesh"), strategies
    assert len(guesses) >= 2 and all(g is None for g in guesses), guesses
    assert len(checks) >= 2 and plan.meta["success"], plan.meta["attempts"]
