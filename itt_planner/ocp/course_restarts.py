"""The restart strategies of the full-course solve (`course_problem.solve_plan`), the
budget their solver runs share (`Budget`; `Budget.resume_at`: a run resumed from a
primal-dual point moved onto another mesh, for the warm re-solve and the 3D refinement)
and the verification of each plan (`CourseSolve.finish`).

Restart strategies (issue 14 item 2, issue 18 item 3), in this order, each only when the
previous attempt did not end converged and verified, all within the budget (the first
start may use `_FIRST_SHARE` of it):

- a re-solve of the rest of the course with the primal-dual point of the plan it
  starts from (`solve_plan(warm=)`, `course_nlp.PrimalDual`): first a run resumed from
  that point on that plan's mesh cut at the start; on the Zwift Bologna ride 8-22
  iterations instead of 44-116 (bench/RESULTS.md, 2026-12-01, issue 14 re-solves);
  if it does not converge, or its plan fails the verification, the strategies below on
  a mesh built for the start, from the guess. From the old mesh, a rider at 1 m/s before
  the hairpin test course's corner stopped at the caps; a Sauerland 1D re-solve on the
  line, warm from a point 2 km behind the rider, converged onto an artefact (2 -> 14 m/s
  in one 10 m RK4 step), and its refinement found it again; on a mesh for the start from
  the plan in force: 106 iterations, verified (bench/RESULTS.md, 2026-12-03, third);
- coarse mesh first (3D, cold, no given guess, no start, more than `_COARSE_MIN_NODES`
  nodes): solve on every other node of the mesh (intervals up to 2 h_max_m, two RK4
  substeps each: half the KKT system), then resume on the full mesh from that
  primal-dual point moved onto it (`Budget.resume_at`; the fine nodes hold the coarse
  ones, so only the new middle nodes are interpolated). The coarse run places the
  active arcs (C11, C15, C16, W' = 0) at about half the cost per iteration, which a
  cold start on the full mesh forms a node or two per iteration (2026-12-01, H5). If
  the coarse run does not converge, the cold start on the full mesh as before;
- windows first (3D, cold as above, a course longer than `OcpSettings.window_min_m`):
  the 1D plan (its barrier never monotone, `OcpSettings.never_monotone`), then the 3D
  model on overlapping windows of ~12 km of work (shorter among corners) from it
  (barrier capped, `OcpSettings.window_mu_max`), each cold on its own nodes of the full
  mesh (no coarse mesh first: on Ardennes that failed in 2 of 4 windows of 15 km, and a
  window's own run costs less than a coarse and a fine one, bench/RESULTS.md,
  2026-12-02, H3), then a run on the full mesh resumed from their stitched primal-dual
  point (`course_windows`, why there). A window that gives up early, or still runs at
  1.5 times the iterations of the slowest window before it
  (`OcpSettings.window_max_iter`), is restarted with the smaller bound push below; one
  that still fails, from the other guess (the arc guess or the 1D plan). If the 1D plan
  or a window does not converge, the coarse mesh first or the cold start as without;
- early failure (`solver.SolveResult.gave_up_early`): the same start with a smaller
  bound push (on short courses the 3D model ended in Restoration_Failed with IPOPT's
  default push and converged in 39-64 iterations with 1e-4);
- 1D models (`CourseSolve.one_d`): a cold start with the adaptive barrier never
  falling back to its monotone mode (`solver.full_course_solver(never_monotone=True)`:
  the Shanghai ride's barrier collapse, why there), then a cold start on a mesh of half
  the spacing (the 1D model on the 9 km hilly route of bench_convergence with 20 m
  intervals stopped at 569 iterations; restarted on 10 m it converged in 65);
- 3D stopped by its share of the budget: resume from the run's last primal-dual point
  (multipliers passed back, small barrier, no push off the bounds: the solver's resume
  option set, `full_course_solver(resume=True)`) with `_RESUME_SHARE` of what is left.
  A capped 3D run is mostly still converging (it forms the active arcs of C15, C16,
  W' >= 0 and the road edges a node or two per iteration); a restart from scratch
  threw that away: the hairpin course (`sim.hairpin_course`) with the paper rider ran
  365 iterations capped, 4 short of converging, then 190 from the 1D plan, capped again
  (609 in all); resumed it converges in 365 + 4 (bench/RESULTS.md, 2026-12-01, H5:
  the resume costs what one uninterrupted run would);
- 3D that failed (not capped) without a given guess: warm start from the 1D plan of
  the same course (the 1D model has no roll mode and converges in a fraction of the
  time; its speed and power profile is most of the 3D solution away from corners).
  Only as a restart: as the first start it did not pay on verona-like with the
  issue-18 rider (448 iterations from the 1D plan against 301 cold, 2026-12-01);
- still capped: continue from the last iterate with IPOPT's acceptable level relaxed
  (`_RELAXED_TOL`: 1e-4 in 5 consecutive iterations), which the verification then
  has to confirm;
- converged but not verified: the mesh refined where the plan is slow, and re-solved
  (`course_refine`).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from functools import partial

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import Rider
from itt_planner.model.wprime import WPrimeModel
from itt_planner.ocp.course_budget import Budget
from itt_planner.ocp.course_nlp import (
    CourseNlp,
    PrimalDual,
    course_nlp,
    mesh_substeps,
    to_plan,
)
from itt_planner.ocp.course_settings import OcpSettings, Start
from itt_planner.ocp.course_windows import (
    end_reserve,
    plan_between,
    plan_windows,
    stitch,
    window_corners_per_km,
    window_iter_cap,
    window_start,
)
from itt_planner.ocp.mesh import build_mesh
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import INVALID_RAW_STATUS, PlanStatus, SolveResult
from itt_planner.ocp.verify import Verification, verify_plan

log = logging.getLogger(__name__)

#: A solve that gave up early (`SolveResult.gave_up_early`) is restarted once with this
#: push: on short courses (0.6-0.8 km, typical and climber riders) the 3D model ended in
#: Restoration_Failed with the default push and converged in 39-64 iterations with it.
_RETRY_BOUND_PUSH = 1e-4
#: Share of the budget the first start may use (the rest is for the restarts).
_FIRST_SHARE = 0.6
#: Coarse mesh first (module docstring): above this many nodes, and the share of the
#: budget the coarse run may use. Bologna (4,309 nodes) converged on 2,155 nodes in 133
#: iterations at ~0.5x the CPU per iteration, then in 79 on the full mesh, against 271-307
#: cold (bench/RESULTS.md, 2026-12-02, helper A). Shorter courses are cheap cold, and the
#: short technical ones have local optima a coarse mesh picks differently
#: (descent-hairpins at double spacing: +0.27 %, 2026-12-01).
_COARSE_MIN_NODES = 3000
_COARSE_SHARE = 0.3
#: Share of the budget left that a capped 3D run may use to resume (module docstring).
_RESUME_SHARE = 0.8
#: Share of the budget of the first run from a previous plan's primal-dual point
#: (`solve_plan(warm=)`): the restarts keep enough for a start from its primal point.
_WARM_SHARE = 0.3
#: IPOPT's acceptable tolerance of the relaxed restart (module docstring).
_RELAXED_TOL = 1e-4


@dataclass
class CourseSolve:
    """One `solve_plan` call: its inputs, the restart strategies of the module docstring
    in their order, and the verification of each plan (`finish`). `solve_1d`: the 1D
    plan of the same solve with other settings (`course_problem.solve_plan`, passed in:
    this module is below it)."""

    course: Course
    rider: Rider
    conditions: Conditions
    settings: OcpSettings
    model: str
    guess: Plan | None
    start: Start | None
    free_start: tuple[str, ...]
    v0: float
    budget: Budget
    solve_1d: Callable[[OcpSettings], Plan]
    #: The primal-dual point of the last plan `finish` made, and its verification.
    point: PrimalDual | None = None
    check: Verification | None = None

    @property
    def start_m(self) -> float:
        return 0.0 if self.start is None else self.start.s_m

    @property
    def one_d(self) -> bool:
        """A 1D model ("1d", or "1dline" on a line): no roll mode, cheap cold starts."""
        return self.model != "3d"

    def mesh(self, cap: np.ndarray, scale: float = 1.0) -> np.ndarray:
        """The mesh with the spacing scaled by `scale` (0.5: half the spacing)."""
        st = self.settings
        h_max = st.h_max_m if self.model == "3d" else st.h_max_1d_m
        uniform = None if st.uniform_m is None else st.uniform_m * scale
        return build_mesh(self.course, st.h_min_m, h_max * scale, uniform,
                          start_m=self.start_m, h_cap_m=cap)

    def nlp(self, nodes: np.ndarray, guess: Plan | None) -> CourseNlp:
        return course_nlp(self.course, self.rider, self.conditions, self.settings, self.model,
                          nodes, self.v0, self.start, guess, self.free_start)

    def warm(self, prob: CourseNlp, point: PrimalDual, cap: np.ndarray
             ) -> tuple[CourseNlp, Plan]:
        """A re-solve from the primal-dual point of the plan it starts from, `prob` on
        that plan's mesh cut at the start; if it does not converge, or its plan fails
        the verification, `first` on a mesh built for the start. Returns the NLP the
        plan belongs to, and the plan (`finish`ed)."""
        res = self.budget.resume_at("warm", prob, point, share=_WARM_SHARE)
        if res.converged:
            plan = self.finish(prob, res)
            if plan.status != PlanStatus.INVALID.value or not self.budget.usable():
                return prob, plan
        # The restarts on a mesh of their own (module docstring: a split launch, and a
        # warm plan on an artefact of the old mesh).
        prob, res = self.first(self.nlp(self.mesh(cap), self.guess), cap)
        return prob, self.finish(prob, res)

    def first(self, prob: CourseNlp, cap: np.ndarray) -> tuple[CourseNlp, SolveResult]:
        """The first start and the restarts before a verification (module docstring):
        the NLP the result belongs to, and the result."""
        run, usable = self.budget.run, self.budget.usable
        cold = prob.w_guess
        res = self._from_windows(prob) if self._windows_pay(prob) else None
        if res is None and self._coarse_pays(prob):
            res = self._from_coarse(prob)
        if res is None or res.status is PlanStatus.FAILED:
            # The first start gets `_FIRST_SHARE` of the budget, so that a restart has some left.
            res = run("guess" if self.guess is not None else "cold", prob, cold,
                      share=_FIRST_SHARE, never_monotone=self.settings.never_monotone)
        if res.gave_up_early and usable():
            res = run("smaller bound push", prob, cold, bound_push=_RETRY_BOUND_PUSH, share=0.5)
        if res.status is PlanStatus.CAPPED and self.model == "3d" and usable():
            # Capped 3D runs were mostly still converging: go on from where it stopped.
            res = run("resume", prob, res.w, share=_RESUME_SHARE, resume=res)
        if not res.converged and self.one_d and not self.settings.never_monotone and usable():
            res = run("never-monotone barrier", prob, cold, share=0.5, never_monotone=True)
        if not res.converged and self.one_d and usable():
            prob = self.nlp(self.mesh(cap, 0.5), self.guess)
            res = run("finer mesh", prob, prob.w_guess, share=0.7)
        if (res.status is PlanStatus.FAILED and self.model == "3d" and self.guess is None
                and usable()):
            res = self._warm_from_1d(prob, res)
        if res.status is PlanStatus.CAPPED and usable():
            res = run("relaxed tolerance", prob, res.w, bound_push=_RETRY_BOUND_PUSH,
                      acceptable_tol=_RELAXED_TOL)
        return prob, res

    def _coarse_pays(self, prob: CourseNlp, min_nodes: int | None = None) -> bool:
        """A cold 3D start from the default guess on a mesh of more than `min_nodes`
        (default `_COARSE_MIN_NODES`) nodes (module docstring: coarse mesh first)."""
        return (self.model == "3d" and self.guess is None and self.start is None
                and len(prob.nodes) > (_COARSE_MIN_NODES if min_nodes is None else min_nodes))

    def _windows_pay(self, prob: CourseNlp) -> bool:
        """Windows first (module docstring): a cold 3D start on a long course."""
        return (self._coarse_pays(prob, 0)
                and prob.nodes[-1] - prob.nodes[0] > self.settings.window_min_m)

    def _from_windows(self, prob: CourseNlp) -> SolveResult | None:
        """Solve the 1D plan, then the 3D model on overlapping windows from it
        (`course_windows`), then resume on `prob` from their stitched point; None when
        the 1D plan or a window did not converge (the caller then goes on as without)."""
        base = self._plan_1d("1d plan for the windows", 0.25, never_monotone=True)
        if not base.meta.get("success"):
            return None
        st, run, usable = self.settings, self.budget.run, self.budget.usable
        apex = np.array([c.apex_s_m for c in self.course.corners])
        wins = plan_windows(prob.nodes, st.window_m, st.window_overlap_m, apex, st.window_corner_m)
        runs: list[SolveResult] = []
        win_nlp: CourseNlp | None = None
        for k, win in enumerate(wins):
            if not usable():
                return None
            nodes = prob.nodes[win.first: win.last + 1]
            start = None if win_nlp is None else window_start(
                win_nlp.tr.model.states, win_nlp.tr.layout, runs[-1],
                win.first - wins[k - 1].first, float(nodes[0]))
            reserve = end_reserve(base, float(nodes[-1]), self.rider.w_prime_j,
                                  st.e_final_min, last=k == len(wins) - 1)
            # Among dense corners the default (arc) guess, elsewhere the 1D plan (module
            # docstring: the 1D plan's corner speeds do not match the guess's lean there).
            dense = (window_corners_per_km(nodes, apex) > st.window_arc_guess_corners_per_km)
            label = f"window {k + 1}/{len(wins)} ({nodes[0] / 1e3:.1f}-{nodes[-1] / 1e3:.1f} km"
            # Each window gets an equal share of what is left, one share kept for the polish.
            share = 1.0 / (len(wins) - k + 1)
            win_nlp, res = self._solve_window(label, base, dense, reserve, start, nodes, share,
                                              window_iter_cap(st, [r.iterations for r in runs]))
            if not res.converged:
                return None
            runs.append(res)
        point = stitch(prob.tr.layout, wins, runs)
        return run("polish from the windows", prob, point.w, share=_FIRST_SHARE, resume=point,
                   tol=st.window_polish_tol)

    def _solve_window(self, label: str, base: Plan, dense: bool, reserve: float,
                      start: Start | None, nodes: np.ndarray, share: float, cap: int
                      ) -> tuple[CourseNlp, SolveResult]:
        """One window's runs (`_window_nlp`), `share` of the budget left each: from the
        arc guess if `dense`, else from the 1D plan `base` with the barrier capped
        (`OcpSettings.window_mu_max`); after an early failure or at `cap` iterations
        (`course_windows.window_iter_cap`) again with the smaller bound push; capped,
        resumed; still not converged, all that once more from the other guess (the
        Sauerland ride's window at 77-89 km, calibrated rider, ended Restoration_Failed
        from the 1D plan with both bound pushes)."""
        for arc in (dense, not dense):
            nlp = self._window_nlp(None if arc else base, reserve, start, nodes)
            name = f"{label}{', arc guess' if arc else ''})"
            run = partial(self.budget.run, mu_max=None if arc else self.settings.window_mu_max)
            res = run(name, nlp, nlp.w_guess, share=share, max_iter=cap)
            if (res.gave_up_early or res.iterations >= cap) and self.budget.usable():
                res = run(f"{name}, smaller bound push", nlp, nlp.w_guess,
                          bound_push=_RETRY_BOUND_PUSH, share=share)
            if res.status is PlanStatus.CAPPED and self.budget.usable():
                res = run(f"{name}, resumed", nlp, res.w, share=0.5, resume=res)
            if res.converged or not self.budget.usable():
                break
        return nlp, res

    def _from_coarse(self, prob: CourseNlp) -> SolveResult | None:
        """Solve on every other node of `prob`'s mesh (and its last) from the default
        guess, then resume on `prob` from that point (`Budget.resume_at`); None when the
        coarse run did not converge (the caller then starts cold on `prob`)."""
        nodes = np.append(prob.nodes[:-1:2], prob.nodes[-1])
        coarse = self.nlp(nodes, None)
        res = self.budget.run("coarse mesh", coarse, coarse.w_guess, share=_COARSE_SHARE)
        if not res.converged or res.lam_x is None or res.lam_g is None or not self.budget.usable():
            return None
        point = PrimalDual(nodes, res.w, res.lam_x, res.lam_g)
        return self.budget.resume_at("from the coarse mesh", prob, point, share=_FIRST_SHARE)

    def _window_nlp(self, base: Plan | None, reserve: float, start: Start | None,
                    nodes: np.ndarray) -> CourseNlp:
        """A window's NLP on `nodes`: from `start` (the course's start if None), leaving
        `reserve` of W' at its end, from the 1D plan `base` as its guess (the default
        guess if None)."""
        guess = None if base is None else plan_between(base, float(nodes[0]), float(nodes[-1]))
        return course_nlp(self.course, self.rider, self.conditions,
                          dataclasses.replace(self.settings, e_final_min=reserve), "3d", nodes,
                          self.v0 if start is None else start.state["v"], start, guess)

    def _plan_1d(self, strategy: str, share: float, never_monotone: bool = False) -> Plan:
        """The 1D plan of the same solve (`share` of the CPU left at most), an attempt;
        `never_monotone`: its first run's (`OcpSettings.never_monotone`)."""
        _, secs = self.budget.left()
        st, left_m = self.settings, self.course.length_m - self.start_m
        cpu0 = time.process_time()
        base = self.solve_1d(dataclasses.replace(
            st, max_iter=None, max_cpu_time_s=min(secs * share, st.budget("1d", left_m)[1]),
            never_monotone=never_monotone))
        self.budget.attempts.append({
            "strategy": strategy, "status": base.solver_status,
            "outcome": PlanStatus.of(base.solver_status).value, "iterations": base.iterations,
            "n_nodes": base.n_nodes, "time_s": round(base.solve_time_s, 3),
            "cpu_s": round(time.process_time() - cpu0, 3)})
        return base

    def _warm_from_1d(self, prob: CourseNlp, res: SolveResult) -> SolveResult:
        """Solve the 1D plan (a third of the CPU left at most) and start from it."""
        base = self._plan_1d("1d plan for a warm start", 1 / 3)
        if base.meta.get("success") and self.budget.usable():
            warm = self.nlp(prob.nodes, base)
            return self.budget.run("warm from 1d", warm, warm.w_guess)
        return res

    def finish(self, prob: CourseNlp, res: SolveResult) -> Plan:
        """The plan of one solver run, verified; its status and figures in `meta`."""
        course, rider, conditions = self.course, self.rider, self.conditions
        settings = self.settings
        attempts = self.budget.attempts
        status, raw = res.status, res.raw_status
        meta = {"course": course.name, "course_sha256": course.source_sha256,
                "rider": asdict(rider), "conditions": asdict(conditions),
                "settings": {k: (v.value if isinstance(v, WPrimeModel) else v)
                             for k, v in asdict(settings).items()},
                "objective": res.objective, "ipopt_status": raw, "attempts": list(attempts)}
        # A run that raised has no multipliers: the plan's costate is then 0.
        lam_g = res.lam_g if res.lam_g is not None else np.zeros(len(prob.tr.lbg))
        plan = to_plan(prob.tr, res.w, prob.p, lam_g, prob.nodes, rider, status=raw,
                       iterations=sum(a["iterations"] for a in attempts), solve_time_s=0.0,
                       meta=meta)
        check: Verification | None = None
        if settings.verify and np.all(np.isfinite(res.w)):
            check = verify_plan(plan, course, rider, conditions, model=prob.tr.model,
                                substeps=mesh_substeps(plan.model, prob.nodes),
                                wprime_model=settings.wprime_model)
            if status is PlanStatus.CONVERGED and not check.verified:
                status, raw = PlanStatus.INVALID, INVALID_RAW_STATUS
                # Info: `course_refine` goes on from here, and a plan that stays invalid
                # is warned about once, at the end (`course_problem`), and in `attempts`.
                log.info("plan on %s failed its check: %s mismatch %.1fx its tolerance at "
                         "s = %.0f m", course.name, check.worst, check.worst_ratio,
                         check.worst_s_m)
        meta["verification"] = None if check is None else check.as_dict()
        self.check = check
        meta["success"] = status is PlanStatus.CONVERGED
        self.point = None if res.lam_x is None or res.lam_g is None else PrimalDual(
            prob.nodes, res.w, res.lam_x, res.lam_g)
        return dataclasses.replace(plan, solver_status=raw, status=status.value, meta=meta)
