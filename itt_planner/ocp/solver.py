"""The solver seam: every NLP of the project is solved here, and here only is IPOPT named.

Both OCPs (the full-course problem, `course_problem`, and the receding horizon,
`horizon`) hand a `Transcription` and its numeric data to an `NlpSolver` and get a
`SolveResult` back: the iterate, the multipliers, and a `PlanStatus` that code and tests
reason about, with the solver's raw status string, iterations and time beside it.
Swapping IPOPT for another NLP solver touches this module only: the plugin, the option
sets (`full_course_solver`, with its resume from a primal-dual point, `horizon_solver`),
and the mapping of raw statuses onto `PlanStatus`:

- `converged`: `Solve_Succeeded`, or `Solved_To_Acceptable_Level` (IPOPT's acceptable
  tolerances, 10-100x looser; accepted because every full-course plan is then replayed
  by an independent simulation, `verify`, which catches a plan that is not physical);
- `capped`: stopped by the iteration, CPU-time or wall-time budget;
- `failed`: anything else (infeasible, restoration failed, evaluation error, ...);
- `invalid`: the solver converged but the plan failed its verification (`verify`).

A plan carries both: `Plan.status` (this enum's value) and `Plan.solver_status` (IPOPT's
raw string, or `Invalid_Plan` when verification overruled a success).

The solver is built once per option set (a CasADi Function over the transcription's
compiled derivative kernels, cheap to build) and called many times: the horizon builds
its three at start-up and calls them on every replan.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from enum import Enum
from typing import Any

import casadi as ca
import numpy as np

from itt_planner.ocp.transcription import Transcription

#: IPOPT statuses that count as converged (module docstring).
CONVERGED_STATUSES = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
#: IPOPT statuses of a run stopped by its budget.
CAPPED_STATUSES = ("Maximum_Iterations_Exceeded", "Maximum_CpuTime_Exceeded",
                   "Maximum_WallTime_Exceeded")
#: IPOPT statuses of a run that gave up early, which a start further inside the bounds
#: may fix (`SolveResult.gave_up_early`, the full-course problem's first restart).
_EARLY_FAILURES = ("Restoration_Failed", "Error_In_Step_Computation",
                   "Infeasible_Problem_Detected")
#: Raw status a plan gets when the solver converged but verification failed.
INVALID_RAW_STATUS = "Invalid_Plan"
#: Raw status of an iterate with NaN or inf in it (never used).
NON_FINITE_STATUS = "non-finite iterate"


class PlanStatus(str, Enum):  # noqa: UP042  (StrEnum would change str(); a refactor keeps it)
    """What a solve's outcome means for its use (module docstring)."""

    CONVERGED = "converged"
    CAPPED = "capped"
    FAILED = "failed"
    INVALID = "invalid"

    @classmethod
    def of(cls, raw_status: str) -> PlanStatus:
        """Classify a raw solver status (IPOPT's `return_status`, or `Invalid_Plan`)."""
        if raw_status in CONVERGED_STATUSES:
            return cls.CONVERGED
        if raw_status in CAPPED_STATUSES:
            return cls.CAPPED
        if raw_status == INVALID_RAW_STATUS:
            return cls.INVALID
        return cls.FAILED


@dataclass(frozen=True, eq=False)
class SolveResult:
    """One solver run.

    Attributes:
        w: the last iterate (the start itself when the run raised or ended non-finite).
        lam_x, lam_g: multipliers of the simple bounds and of the constraints (None
            when the run raised or ended non-finite).
        objective: the objective at `w` (nan when the run raised).
        status: what the outcome means (`PlanStatus`: converged, capped or failed).
        raw_status: the solver's own status string (`error: ...` when it raised).
        iterations: iterations of this run.
        time_s: wall time of this run.
    """

    w: np.ndarray
    lam_x: np.ndarray | None
    lam_g: np.ndarray | None
    objective: float
    status: PlanStatus
    raw_status: str
    iterations: int
    time_s: float

    @property
    def converged(self) -> bool:
        return self.status is PlanStatus.CONVERGED

    @property
    def gave_up_early(self) -> bool:
        """Stopped early by infeasibility or a failed restoration (not by the budget)."""
        return self.raw_status in _EARLY_FAILURES


class NlpSolver:
    """One NLP solver with fixed options over a transcription; build once, `solve` often.

    Build it with `full_course_solver` or `horizon_solver` (the option sets).
    """

    def __init__(self, name: str, tr: Transcription, options: dict[str, Any]) -> None:
        self._solver = ca.nlpsol(name, "ipopt", tr.nlp, {**tr.derivatives, **options})
        self._lbg, self._ubg = tr.lbg, tr.ubg

    def solve(self, w0: np.ndarray, p: np.ndarray, lbw: np.ndarray, ubw: np.ndarray, *,
              lam_x0: np.ndarray | None = None, lam_g0: np.ndarray | None = None
              ) -> SolveResult:
        """Solve from `w0` (clipped into the bounds `lbw`, `ubw`) with parameters `p`;
        `lam_x0`, `lam_g0`: starting multipliers. Never raises on a solver failure: an
        evaluation error inside CasADi is a `failed` result (`error: ...`)."""
        w0 = np.clip(w0, lbw, ubw)
        warm = {} if lam_x0 is None or lam_g0 is None else {"lam_x0": lam_x0, "lam_g0": lam_g0}
        t0 = time.perf_counter()
        try:
            sol = self._solver(x0=w0, p=p, lbx=lbw, ubx=ubw, lbg=self._lbg, ubg=self._ubg,
                               **warm)
        except RuntimeError as err:
            return SolveResult(w0, None, None, float("nan"), PlanStatus.FAILED,
                               f"error: {err}", 0, time.perf_counter() - t0)
        elapsed = time.perf_counter() - t0
        stats = self._solver.stats()
        iterations = int(stats.get("iter_count", 0))
        w = np.asarray(sol["x"]).ravel()
        if not np.all(np.isfinite(w)):
            return SolveResult(w0, None, None, float("nan"), PlanStatus.FAILED,
                               NON_FINITE_STATUS, iterations, elapsed)
        raw = str(stats.get("return_status", "unknown"))
        return SolveResult(w, np.asarray(sol["lam_x"]).ravel(), np.asarray(sol["lam_g"]).ravel(),
                           float(sol["f"]), PlanStatus.of(raw), raw, iterations, elapsed)


#: Options every IPOPT run of the project shares (quiet, MUMPS, status instead of raise).
_COMMON = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
           "ipopt.linear_solver": "mumps", "error_on_fail": False,
           # Derivatives come from the compiled stage kernels (transcription docstring);
           # the Lagrangian gradient w.r.t. p that nlpsol would build by AD is not needed.
           "no_nlp_grad": True, "calc_lam_p": False}

#: Replans with a previous solution start next to the optimum: a small initial barrier
#: and a start kept inside the bounds it already satisfies. Measured on verona-like
#: (bench/RESULTS.md): median ~20 iterations instead of ~50 with IPOPT's defaults.
#: Without IPOPT's gradient-based NLP scaling: it divided the objective (slack and
#: terminal penalties give gradients of 100-1000) by up to 10x, so the tolerance and the
#: barrier acted on a different problem than the one the weights were tuned on; without
#: it the whole verona-like sweep went from 95 % to 98 % usable replans and the p95
#: latency from 387 to 246 ms (bench/RESULTS.md).
_HORIZON_WARM = {"mu_init": 1e-4, "mu_strategy": "monotone", "warm_start_init_point": "yes",
                 "warm_start_bound_push": 1e-6, "warm_start_mult_bound_push": 1e-6,
                 "warm_start_slack_bound_push": 1e-6, "nlp_scaling_method": "none"}
#: The first replan (or one after a failure) starts from the full-course plan, which was
#: solved with the roll dynamics: a larger barrier lets IPOPT move away from it (with the
#: warm settings 1 of 12 verona-like windows failed, with these none).
_HORIZON_COLD = {"mu_init": 1e-2, "mu_strategy": "monotone", "nlp_scaling_method": "none"}


#: Cap on the adaptive barrier parameter (IPOPT's default 1e5) of the 1D model. Measured
#: with the issue-18 rider (bench/RESULTS.md, 2026-12-01): the adaptive update let the
#: barrier wander up and took 214 iterations on a 3.9 km climb at half the mesh spacing
#: (29 with the cap), 284 on rovereto-like at half spacing (38), and on a 9 km hilly
#: route converged to a plan that failed its verification (63 iterations, verified, with).
_MU_MAX_1D = 0.1
#: MUMPS's fill-reducing ordering of the full-course KKT system: approximate minimum
#: degree (AMD) instead of MUMPS's automatic choice. The linear solver is ~75 % of a 3D
#: full-course iteration (IPOPT's timing statistics, Bologna 16 km, 4,309 nodes: 61 of
#: 81 s user CPU, factorizations 2-5 per iteration for the inertia correction); on the
#: banded multiple-shooting KKT matrix AMD factors it faster than the automatic choice,
#: METIS, PORD, AMF or QAMD (bench/RESULTS.md, 2026-12-02, helper A). Same iterates to
#: rounding (40 iterations: identical objective); a full run can then take another
#: barrier path, like any change of rounding.
_FULL_COURSE_MUMPS = {"ipopt.mumps_pivot_order": 0}
#: Continue a run from its last primal-dual point (`course_problem`'s resume after a
#: capped 3D run): the multipliers are passed in and kept, the barrier starts small, the
#: point is not pushed off its bounds.
_RESUME = {"warm_start_init_point": "yes", "mu_init": 1e-4, "warm_start_bound_push": 1e-6,
           "warm_start_bound_frac": 1e-6, "warm_start_mult_bound_push": 1e-6,
           "warm_start_slack_bound_push": 1e-6, "warm_start_slack_bound_frac": 1e-6}


#: The adaptive barrier's globalization of the restart after a 1D run that did not
#: converge (`full_course_solver(never_monotone=True)`): IPOPT's default ("obj-constr-filter")
#: let the barrier fall to 1e-11 by iteration ~100 with the infeasibility still ~0.6 on the
#: 80 km Shanghai ride, then crawled to the CPU cap (708 iterations); without the
#: fall-back to the monotone mode it converged in 60. Not a default: over the convergence
#: study's courses it was better on some and worse on others (bologna 81 -> 257
#: iterations; bench/RESULTS.md, 2026-12-02, lead), so only as a restart.
_NEVER_MONOTONE = {"ipopt.adaptive_mu_globalization": "never-monotone-mode"}


def full_course_solver(tr: Transcription, *, max_iter: int, max_cpu_time_s: float, tol: float,
                       bound_push: float, acceptable_tol: float | None = None,
                       resume: bool = False, never_monotone: bool = False,
                       mu_max: float | None = None) -> NlpSolver:
    """The solver of one full-course attempt (`course_problem.solve_plan`).

    `bound_push` (= IPOPT's `bound_frac`): how far the initial point is moved inside its
    bounds; IPOPT's default 1e-2 first (1e-4 took 116 instead of 75 iterations on
    verona-like 3D), 1e-4 as a restart after an early failure (see `course_problem`).
    `acceptable_tol`: IPOPT's acceptable level (default: IPOPT's own 1e-6 ... with 15
    acceptable iterations). The 1D model's barrier is capped (`_MU_MAX_1D`), any
    model's at `mu_max` if given (a 3D window from the 1D plan, `course_restarts`). `resume`:
    the run continues a previous one from its primal-dual point (`_RESUME`; the caller
    passes the multipliers to `solve`). `never_monotone`: the adaptive barrier without
    its fall-back to the monotone mode (`_NEVER_MONOTONE`). The budget is at least one
    iteration and one CPU second.
    """
    opts = {**_COMMON, "ipopt.max_iter": max(int(max_iter), 1),
            "ipopt.max_cpu_time": max(max_cpu_time_s, 1.0), "ipopt.tol": tol,
            # Measured on verona-like: adaptive 75 iterations (3D) / 43 (1D), monotone 239 / >400.
            "ipopt.mu_strategy": "adaptive",
            "ipopt.bound_push": bound_push, "ipopt.bound_frac": bound_push,
            **_FULL_COURSE_MUMPS}
    if tr.model.name == "1d":
        opts["ipopt.mu_max"] = _MU_MAX_1D
    if mu_max is not None:
        opts["ipopt.mu_max"] = mu_max
    if acceptable_tol is not None:
        opts |= {"ipopt.acceptable_tol": acceptable_tol, "ipopt.acceptable_iter": 5}
    if resume:
        opts |= {f"ipopt.{k}": v for k, v in _RESUME.items()}
    if never_monotone:
        opts |= _NEVER_MONOTONE
    return NlpSolver(f"ocp_{tr.model.name}_{tr.layout.n_intervals}", tr, opts)


def horizon_solver(tr: Transcription, name: str, *, warm: bool, max_iter: int,
                   max_wall_time_s: float, tol: float, acceptable_iter: int) -> NlpSolver:
    """The solver of one kind of horizon attempt: `warm` from the previous solution
    (`_HORIZON_WARM`), else from the plan (`_HORIZON_COLD`)."""
    start = _HORIZON_WARM if warm else _HORIZON_COLD
    return NlpSolver(name, tr, {
        **_COMMON, "ipopt.max_iter": max_iter, "ipopt.tol": tol,
        "ipopt.acceptable_tol": 10 * tol, "ipopt.acceptable_iter": acceptable_iter,
        "ipopt.max_wall_time": max(max_wall_time_s, 1e-3),
        **{f"ipopt.{k}": v for k, v in start.items()}})
