"""The last restart strategy of the full-course solve (`course_restarts`): a plan that
converged but failed its verification is re-solved on a finer mesh.

Why: a speed the mesh does not resolve, e.g. a rider slowed far below the guess, or the
3D launch (one 1 m RK4 step from 1 m/s gains ~0.7 m/s). The mesh is refined where the
plan is slow (`mesh.speed_spacing_m` on the plan's speeds and tyre forces) and the plan
re-solved, at most `_REFINE_ROUNDS` times.

- 1D models (`CourseSolve.one_d`: the 1D, and the 1D on a line that knows its corners,
  "1dline"): a mesh built for that cap, from the solve's guess, not from the invalid
  plan (it rides on the artefact); still invalid: the whole mesh at half the spacing (at
  20 m the 1D plans of bologna and rovereto-like were invalid, 2026-12-01). The 1D on a
  line took the 3D's way until 2026-12-03: a Sauerland re-solve's plan that jumped from
  2 to 14 m/s in one 10 m interval was re-solved from itself on its nodes split, and
  rode the same jump (bench/RESULTS.md, 2026-12-03, lead, third session).
- 3D: the plan's nodes with the slow ones split (`course_nlp.cut_nodes`) and those with
  a lateral, heading or roll defect over tolerance (`mesh.split_spacing_m`: an Ardennes
  re-solve's roll 2x where the speed rule split nothing), resumed from the plan's
  primal-dual point moved onto them (`cut_point`), from its primal point if that fails.
  A mesh built afresh kept 2 of 348 nodes (test hairpin, 600 m straights), the plan on
  it sat off the active arcs of C11/C15/C16: a rider limited to 4 m/s^2 ended
  Infeasible_Problem_Detected after 419 iterations (split and resumed: 7; issue 18).
"""

from __future__ import annotations

import numpy as np

from itt_planner.ocp.course_nlp import CourseNlp, cut_nodes
from itt_planner.ocp.course_restarts import CourseSolve
from itt_planner.ocp.guess import plan_spacing_cap
from itt_planner.ocp.mesh import split_spacing_m
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import PlanStatus

#: Mesh refinements after a failed verification (module docstring).
_REFINE_ROUNDS = 2


def refine(solve: CourseSolve, plan: Plan, prob: CourseNlp, cap: np.ndarray) -> Plan:
    """`plan` (of `prob`, from `solve`) if it is not invalid, else the plan re-solved on
    a finer mesh (module docstring); `cap`: the spacing cap the mesh was built with."""
    usable, run = solve.budget.usable, solve.budget.run
    for _ in range(_REFINE_ROUNDS):
        if plan.status != PlanStatus.INVALID.value or not usable():
            break
        cap = np.minimum(cap, plan_spacing_cap(solve.course, plan, solve.rider,
                                               solve.conditions))
        if solve.check is not None and solve.check.unresolved_s_m:  # 3D only
            cap = np.minimum(cap, split_spacing_m(solve.course.s_m, prob.nodes,
                                                  solve.check.unresolved_s_m))
        nodes = (solve.mesh(cap) if solve.one_d
                 else cut_nodes(prob.nodes, solve.start_m, 0.0, solve.course.s_m, cap))
        # Any node added counts: a hard launch on St John's asked 10 more of 10,340 (a
        # threshold of 0.1 % read that as "no finer mesh" and left the plan invalid).
        if len(nodes) <= len(prob.nodes):
            break  # the plan's speeds ask for no finer mesh: the mismatch is not the step
        prob = solve.nlp(nodes, solve.guess if solve.one_d else plan)
        res = None
        if not solve.one_d and solve.point is not None:  # the plan's point, resumed
            res = solve.budget.resume_at("refined where slow, resumed", prob, solve.point,
                                         share=0.5)
        if res is None or (not res.converged and usable()):
            res = run("refined where slow", prob, prob.w_guess)
        plan = solve.finish(prob, res)
    if plan.status == PlanStatus.INVALID.value and solve.one_d and usable():
        # Still on an artefact: the whole mesh at half the spacing (bologna at 20 m).
        prob = solve.nlp(solve.mesh(cap, 0.5), solve.guess)
        plan = solve.finish(prob, run("finer mesh", prob, prob.w_guess))
    return plan
