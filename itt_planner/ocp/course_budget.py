"""The solver runs of one full-course solve (`course_problem.solve_plan`) and the
iteration and CPU budget they share (`Budget`): each run through the solver seam
(`solver.full_course_solver`), recorded as an attempt (`Plan.meta["attempts"]`), and
`Budget.resume_at`, a run resumed from a primal-dual point moved onto another mesh (the
warm re-solve, the coarse mesh first, the 3D refinement). The restart strategies that
use it: `course_restarts`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from itt_planner.ocp.course_nlp import CourseNlp, PrimalDual, cut_point
from itt_planner.ocp.solver import SolveResult, full_course_solver

log = logging.getLogger(__name__)

#: IPOPT's bound_push = bound_frac (how far the initial point is moved inside its
#: bounds): IPOPT's default 1e-2 first. 1e-4 took 116 instead of 75 iterations on
#: verona-like 3D (and ended 0.08 % slower, in another local optimum), and 127 instead of
#: 61 on rovereto-like 1D (34 instead of 43 on verona-like 1D).
BOUND_PUSH = 1e-2


@dataclass
class Budget:
    """The solver runs of one `solve_plan` call, sharing its iteration and CPU budget."""

    max_iter: int
    seconds: float
    cpu_start: float
    tol: float
    label: str
    attempts: list[dict[str, Any]] = field(default_factory=list)

    def left(self) -> tuple[int, float]:
        used = sum(a["iterations"] for a in self.attempts)
        return self.max_iter - used, self.seconds - (time.process_time() - self.cpu_start)

    def usable(self) -> bool:
        """Enough left for another attempt."""
        its, secs = self.left()
        return its > 10 and secs > 1.0

    def run(self, strategy: str, pr: CourseNlp, w0: np.ndarray, share: float = 1.0,
            bound_push: float = BOUND_PUSH, acceptable_tol: float | None = None,
            resume: SolveResult | None = None, never_monotone: bool = False,
            max_iter: int | None = None, mu_max: float | None = None,
            tol: float | None = None) -> SolveResult:
        """One solver run from `w0` with `share` of what is left of the budget, and at
        most `max_iter` iterations if given; `resume`: a previous run on `pr` to continue
        from its primal-dual point (its multipliers too) instead of a fresh start;
        `mu_max`: a cap on the adaptive barrier (`solver.full_course_solver`); `tol`:
        IPOPT's tolerance of this run instead of the solve's."""
        its, secs = self.left()
        its = int(its * share) if max_iter is None else min(int(its * share), max_iter)
        t0, c0 = time.perf_counter(), time.process_time()
        solver = full_course_solver(pr.tr, max_iter=its,
                                    max_cpu_time_s=secs * share,
                                    tol=self.tol if tol is None else tol,
                                    bound_push=bound_push, acceptable_tol=acceptable_tol,
                                    resume=resume is not None,
                                    never_monotone=never_monotone, mu_max=mu_max)
        res = solver.solve(w0, pr.p, pr.lbw, pr.ubw,
                           lam_x0=None if resume is None else resume.lam_x,
                           lam_g0=None if resume is None else resume.lam_g)
        # "outcome" is what the attempt means (`PlanStatus`), "status" the solver's words.
        self.attempts.append({"strategy": strategy, "status": res.raw_status,
                              "outcome": res.status.value, "iterations": res.iterations,
                              "n_nodes": len(pr.nodes),
                              "time_s": round(time.perf_counter() - t0, 3),
                              "cpu_s": round(time.process_time() - c0, 3)})
        if not res.converged:
            log.info("%s, %s: %s after %d iterations", self.label, strategy, res.raw_status,
                     res.iterations)
        return res

    def resume_at(self, strategy: str, pr: CourseNlp, point: PrimalDual, share: float
                  ) -> SolveResult:
        """One run on `pr` resumed from `point`, a converged run's primal-dual point on
        another mesh, moved onto `pr`'s nodes (`course_nlp.cut_point`: `pr.nodes` are
        `point.nodes` cut and split by `course_nlp.cut_nodes`), node 0 at `pr`'s start."""
        cut = cut_point(pr.tr, point, pr.nodes, pr.w_guess[: pr.tr.layout.nx])
        return self.run(strategy, pr, cut.w, share=share, resume=cut)
