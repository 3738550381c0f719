"""The minimum-time pacing-and-cornering OCP over a whole course (model.md section 5).

`solve_plan(course, rider, conditions, settings, model="3d"|"1d"|"1dline") -> Plan`
("1dline": the 1D model on a fixed line that knows its corners, solved on a line's
course: `ocp.line_plan`, `model.dynamics.build_1d_line`):

1. mesh: non-uniform nodes (`mesh.build_mesh`: ~1 m in corners, up to `h_max_m` on
   straights) and the road data per interval;
2. NLP: direct multiple shooting with RK4 (`course_nlp`, `transcription.transcribe`,
   why in its docstring), hard path constraints C11-C16;
3. solve: through the solver seam (`solver.full_course_solver`: IPOPT, MUMPS) from a
   physically sensible initial guess (a speed profile that respects the grip limit in
   corners, steady lean and steering), or from an existing `Plan` interpolated onto the
   new mesh (`guess=`, e.g. a coarse-mesh plan for a mesh study: `guess.plan_guess`),
   with an iteration and time budget scaled to the course length
   (`OcpSettings.budget`), so bad settings end with a solver status instead of a hang;
4. verify: every plan is replayed by an independent simulation (`verify.verify_plan`);
   a converged plan that fails it is `invalid` (`solver.PlanStatus`), never a success.

Restart strategies (issue 14 item 2, issue 18 item 3), the budget their runs share and
the verification of each plan: `course_restarts` (the refinement of a plan that fails it:
`course_refine`). A re-solve of the rest of the course
can start from the primal-dual point of the plan it leaves (`solve_plan(warm=)`).

Boundary conditions and launch: `course_nlp`.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Sequence

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.errors import SolveError
from itt_planner.model.conditions import Conditions
from itt_planner.model.dynamics import MODELS
from itt_planner.model.rider import Rider
from itt_planner.ocp.course_budget import Budget
from itt_planner.ocp.course_nlp import PrimalDual, check_inputs, cut_nodes, start_speed
from itt_planner.ocp.course_refine import refine
from itt_planner.ocp.course_restarts import CourseSolve
from itt_planner.ocp.course_settings import OcpSettings, Start
from itt_planner.ocp.guess import speed_spacing_cap
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import PlanStatus

log = logging.getLogger(__name__)


def solve_plan(course: Course, rider: Rider, conditions: Conditions = Conditions(),
               settings: OcpSettings = OcpSettings(), *, model: str = "3d",
               guess: Plan | None = None, start: Start | None = None,
               free_start: Sequence[str] = (), warm: PrimalDual | None = None) -> Plan:
    """Solve the minimum-time OCP over the whole course, verify it, return the `Plan`.

    `start`: solve the rest of the course from a rider's state instead (the pacing
    engine's re-plan after the rider left the plan); the end conditions stay.
    `free_start`: states of `start` left to the solver (`course_nlp.course_nlp`).
    `warm`: the primal-dual point of `guess` (`solve_plan_point`); with a `start`, the
    first run resumes from it on its own mesh cut at the start (`course_nlp.PrimalDual`;
    intervals the start needs finer split) with a share of the budget
    (`course_restarts`); if it does
    not converge, the restarts as usual.

    `guess`: start IPOPT from this plan (any mesh, either model; `plan_guess`) instead
    of the default guess; the boundary conditions stay those of `rider`/`conditions`.
    Only the primal point is warm (a Plan keeps no multipliers), with the same IPOPT
    options as a cold solve (`mu_init` would not matter: the adaptive barrier update
    ignores it; measured identical). Measured on verona-like 3D, uniform 1 m mesh
    (16,800 nodes): cold, not converged in 400 iterations; from the non-uniform plan,
    converged in 687 iterations (642 s CPU).

    The restart strategies (`course_restarts`) share one budget
    (`OcpSettings.budget`). A solve that does not converge, or whose plan fails its
    verification, still returns a Plan: `Plan.status` says which (`solver.PlanStatus`),
    `meta["success"]` is true only for a converged and verified plan, `meta["attempts"]`
    lists every IPOPT run and `meta["verification"]` the replay's figures.

    Raises:
        SolveError: unusable input (status "invalid_input"), e.g. a road narrower than the
            bike, or an unknown model name.
    """
    return solve_plan_point(course, rider, conditions, settings, model=model, guess=guess,
                            start=start, free_start=free_start, warm=warm)[0]


def solve_plan_point(course: Course, rider: Rider, conditions: Conditions = Conditions(),
                     settings: OcpSettings = OcpSettings(), *, model: str = "3d",
                     guess: Plan | None = None, start: Start | None = None,
                     free_start: Sequence[str] = (), warm: PrimalDual | None = None
                     ) -> tuple[Plan, PrimalDual | None]:
    """`solve_plan`, and the primal-dual point of the plan if it converged (for a warm
    re-solve of the rest of the course from it)."""
    if model not in MODELS:
        raise SolveError(f"unknown model {model!r}: choose one of {', '.join(MODELS)}",
                         status="invalid_input")
    check_inputs(course, settings)
    t_start = time.perf_counter()
    cpu_start = time.process_time()
    start_m = 0.0 if start is None else start.s_m
    max_iter, seconds = settings.budget(model, course.length_m - start_m)
    v0 = start_speed(rider, conditions, settings)
    if start is not None:
        v0 = float(start.state.get("v", v0))
    solve = CourseSolve(course, rider, conditions, settings, model, guess, start,
                        tuple(free_start), v0,
                        Budget(max_iter, seconds, cpu_start, settings.tol,
                               f"full-course {model} OCP on {course.name}"),
                        lambda st: solve_plan(course, rider, conditions, st, model="1d",
                                              start=start, free_start=free_start))
    cap = speed_spacing_cap(course, rider, conditions, model, start_m, v0)
    if model == "3d":
        # 3D: a priori no finer than h_min_m. At 0.06 m launch intervals the hairpin took
        # 339 iterations (Restoration_Failed first) instead of 26 + 10 for a refinement
        # after the verification; the 1D model (no roll mode) gains from the fine launch:
        # 24 instead of 98 iterations on the 3.9 km climb of bench_convergence.
        cap = np.maximum(cap, settings.h_min_m)
    warm = warm if start is not None else None
    if warm is None:
        nodes = solve.mesh(cap)
    else:  # the plan's mesh, finer where the start needs it (a slow rider's launch)
        nodes = cut_nodes(warm.nodes, start_m, 0.5 * settings.h_min_m, course.s_m, cap)
    prob = solve.nlp(nodes, guess)
    t_build = time.perf_counter() - t_start
    if warm is None:
        prob, res = solve.first(prob, cap)
        plan = solve.finish(prob, res)
    else:
        prob, plan = solve.warm(prob, warm, cap)
    plan = refine(solve, plan, prob, cap)
    if plan.status != PlanStatus.CONVERGED.value:
        log.warning("full-course %s OCP on %s: %s (%s) after %d iterations", model, course.name,
                    plan.status, plan.solver_status, plan.iterations)
    meta = {**plan.meta, "build_time_s": t_build,
            "budget": {"max_iter": max_iter, "seconds": seconds}}
    if start is not None:
        meta["start"] = {"s_m": start.s_m, "state": dict(start.state), "free": list(free_start)}
    if guess is not None:
        meta["guess"] = {"model": guess.model, "n_nodes": guess.n_nodes,
                         "finish_time_s": guess.finish_time_s}
    return (dataclasses.replace(plan, solve_time_s=time.perf_counter() - t_start, meta=meta),
            solve.point if plan.status == PlanStatus.CONVERGED.value else None)
