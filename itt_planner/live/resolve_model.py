"""Which model a re-solve of the rest of the course solves, in the worker
(`course_replan`): the 3D OCP of the road, or the 1D OCP that knows the corners on the
line of the plan in force (`CourseReplanSettings.model`).

Why the 1D on the line: the 3D re-solves were most of the wall of a deterministic replay
(each is waited for: bench/RESULTS.md, 2026-12-02, issue 14 item 6), and on the line of
the 3D plan in force (its own n(s), `racing_line.offset_course`) a 1D model rides the
same path with the same longitudinal physics at a fraction of the cost. The plain 1D
ignores the corners (model.md section 6): on the Zwift Bologna ride its plans took the
hairpins at up to 3.8 g and were refused 12 times in 13. So the re-solve on the line
is the model that knows the line's corners (`ocp.line_plan.solve_rest_on_line`,
`model.dynamics.build_1d_line`: C15 and C16 at the lateral acceleration v^2 kappa of
the line, at the steady lean). A plan is still used only if it fits C15 and C16 at the
steady lean its speed asks on the line, node by node (`line_plan.line_corners`, the
guard), and converged; otherwise the re-solve is the 3D one. Each plan says which it is
(`meta["resolve"]`: the model, the line, why a 1D plan was refused), and the engine
counts them (`plan_in_force`). On the 14 re-solves of a Zwift Bologna replay, solved
offline from the same starts (bench/RESULTS.md, 2026-12-02, helper H2): all 14
rideable and used, 16.0 s CPU against the 3D's 53.6 s (-70 %); the rest predicted
0.0-1.8 % (median 0.46 %) slower than the 3D's, as the steady lean of C15 stops the
pedalling where the 3D's lean, a state, lags the turn.

`RESOLVE_AUTO`, the default: the 3D where the rest of the course is at most
`CourseReplanSettings.auto_3d_max_m` (20 km), the 1D on the line before. Why: a 3D
re-solve's CPU grows with the rest of the course, and the worker's cap was 60 s then
(now `CourseReplanSettings.ocp_for`, at most 120 s): on the St John's ride (41.3 km,
calibrated rider, bench/RESULTS.md 2026-12-02, lead) the 3D re-solves of 34-41 km took
16-93 iterations and one stopped at the cap after 73, while on Bologna's 16 km every 3D
re-solve converged (8-63 iterations, 0.4-8.5 s CPU). Within 20 km of the finish the 3D's
own corners (the lean a state, not steady) are worth its cost; before, the 1D on the
line is within 0.5 % (median) and a third of the CPU. The St John's replay with `auto`
(bench/RESULTS.md, 2026-12-02, lead): 45 re-solves asked, 45 adopted (29 on the line, 16
in 3D), 0 failed, against 1 failed of 48 with the 3D alone; the wait for them 183 s
against 1,502 s of wall, at the same load. Under `RESOLVE_AUTO` a 3D re-solve that fails
(not converged, or its plan not verified) falls back to the 1D on the line, with the
same guard (`meta["resolve"]["after_3d_failed"]` says so, and the engine counts it): on
the Ardennes ride (57.4 km, calibrated rider) 2 of the 21 3D re-solves within 20 km of
the finish failed (`Invalid_Plan` at 41.1 km, the 60 s cap at 43.7 km) and left the
rider on an older plan.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.course.racing_line import RacingLine, offset_course
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import Rider
from itt_planner.ocp.course_nlp import PrimalDual
from itt_planner.ocp.course_problem import solve_plan_point
from itt_planner.ocp.course_settings import OcpSettings, Start
from itt_planner.ocp.line_plan import line_corners, solve_rest_on_line
from itt_planner.ocp.plan import Plan

log = logging.getLogger(__name__)

#: What a re-solve solves (`CourseReplanSettings.model`): the 3D OCP always, or the 1D
#: that knows the corners on the line of the plan in force where its plan is rideable
#: (module docstring).
RESOLVE_3D = "3d"
RESOLVE_1D_LINE = "1d-line"
RESOLVE_AUTO = "auto"
RESOLVE_MODELS = (RESOLVE_AUTO, RESOLVE_3D, RESOLVE_1D_LINE)


def chosen_model(model: str, rest_m: float, auto_3d_max_m: float) -> str:
    """What a re-solve of `rest_m` of course solves under `model` (`RESOLVE_AUTO`: the 3D
    for a rest of at most `auto_3d_max_m`, module docstring)."""
    if model == RESOLVE_AUTO:
        return RESOLVE_3D if rest_m <= auto_3d_max_m else RESOLVE_1D_LINE
    return model


def on_line(plan: Plan) -> bool:
    """Whether `plan` is a 1D re-solve on a plan's line (`solve_rest_on_line`)."""
    return bool(plan.meta.get("line", {}).get("kind") == "plan")


@dataclass(frozen=True)
class Warm:
    """The primal-dual points a re-solve may start from, one per model (a point fits
    only its own model's NLP): `road_3d` for the 3D, `line` for the 1D on the line.

    Why the 3D one need not be the point of the plan in force: under `RESOLVE_AUTO` the
    plans in force far from the finish are 1D plans on the line, and the first 3D
    re-solve within `auto_3d_max_m` started from their primal point alone. On the
    Ardennes ride (calibrated rider, bench/RESULTS.md 2026-12-02, lead third session)
    four such re-solves 11-17 km from the finish stopped at the 60 s CPU cap. So it
    starts from the point of the last 3D plan instead (`CourseReplanner`), an older
    plan's, as every re-solve starts from the point of a plan the rider has left."""

    road_3d: PrimalDual | None = None
    line: PrimalDual | None = None


class LineCache:
    """The line of the 1D re-solves as a course, built once per line (the worker keeps
    it: the same line for every re-solve after a 3D plan)."""

    def __init__(self) -> None:
        self._key = b""
        self._line: RacingLine | None = None

    def get(self, road: Course, n_m: np.ndarray) -> RacingLine:
        key = np.asarray(n_m, float).tobytes()
        if self._line is None or key != self._key:
            self._key, self._line = key, offset_course(road, n_m, "line of the plan in force")
        return self._line


def solve_rest(model: str, course: Course, rider: Rider, conditions: Conditions,
               settings: OcpSettings, guess: Plan, start: Start, warm: Warm,
               line_n: np.ndarray | None, free_3d: Sequence[str], lines: LineCache
               ) -> tuple[Plan, PrimalDual | None]:
    """The rest of `course` from `start` with `model` (module docstring): the plan (its
    `meta["resolve"]`) and, if it converged, its primal-dual point. `warm`: the points
    each model's solve may start from; `line_n`: the line's offset on the road's grid,
    for `RESOLVE_1D_LINE`, and with `RESOLVE_3D` the line a failed 3D re-solve falls back
    to (`RESOLVE_AUTO`; None: no fall-back); `free_3d`: the states a 3D re-solve leaves
    to the solver (`course_replan.free_states`)."""
    refused = ""
    if model == RESOLVE_1D_LINE and line_n is not None:
        plan, point, refused = _on_line(course, rider, conditions, settings, guess, start,
                                        warm.line, line_n, lines)
        if not refused:
            return plan, point
        log.info("course re-solve from s=%.0f m: the 1D plan on the line refused (%s); "
                 "solving the 3D", start.s_m, refused)
    plan, point = solve_plan_point(course, rider, conditions, settings, model="3d",
                                   guess=guess, start=start, free_start=free_3d,
                                   warm=warm.road_3d)
    plan.meta["resolve"] = {"model": RESOLVE_3D, "line_refused": refused}
    if plan.meta.get("success") or model != RESOLVE_3D or line_n is None:
        return plan, point
    # A failed 3D re-solve (module docstring: `RESOLVE_AUTO`): the line's plan, if rideable.
    failed = f"the 3D re-solve ended {plan.solver_status}"
    line_plan, line_point, refused = _on_line(course, rider, conditions, settings, guess,
                                              start, warm.line, line_n, lines)
    if refused:  # the engine logs and counts it with the failure
        plan.meta["resolve"]["line_refused"] = f"{failed}; the line's: {refused}"
        return plan, point
    line_plan.meta["resolve"]["after_3d_failed"] = failed
    return line_plan, line_point


def _on_line(course: Course, rider: Rider, conditions: Conditions, settings: OcpSettings,
             guess: Plan, start: Start, warm: PrimalDual | None, line_n: np.ndarray,
             lines: LineCache) -> tuple[Plan, PrimalDual | None, str]:
    """The 1D plan on the line `line_n` and why it is refused ("" if it is rideable and
    converged: then its `meta["resolve"]` says so)."""
    line = lines.get(course, line_n)
    plan, point = solve_rest_on_line(line, rider, conditions, settings, guess=guess,
                                     start=start, warm=warm)
    plan, refused = line_corners(plan, line, rider, conditions)
    if plan.converged and not refused:
        plan.meta["resolve"] = {"model": RESOLVE_1D_LINE, "line": line.course.name}
        return plan, point, ""
    return plan, point, refused or f"the 1D plan on the line is {plan.status}"
