"""The solver seam: IPOPT option sets in one place, and what a solve's status means.

IPOPT reports a `return_status` string; code and tests reason about `PlanStatus`
instead:

- `converged`: `Solve_Succeeded`, or `Solved_To_Acceptable_Level` (IPOPT's acceptable
  tolerances, 10-100x looser; accepted because every full-course plan is then replayed
  by an independent simulation, `verify`, which catches a plan that is not physical);
- `capped`: stopped by the iteration, CPU-time or wall-time budget;
- `failed`: anything else (infeasible, restoration failed, evaluation error, ...);
- `invalid`: the solver converged but the plan failed its verification (`verify`).

A plan carries both: `Plan.status` (this enum's value) and `Plan.solver_status` (IPOPT's
raw string, or `Invalid_Plan` when verification overruled a success).
"""

from __future__ import annotations

from enum import Enum
from typing import Any

#: IPOPT statuses that count as converged (module docstring).
CONVERGED_STATUSES = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
#: IPOPT statuses of a run stopped by its budget.
CAPPED_STATUSES = ("Maximum_Iterations_Exceeded", "Maximum_CpuTime_Exceeded",
                   "Maximum_WallTime_Exceeded")
#: Raw status a plan gets when the solver converged but verification failed.
INVALID_RAW_STATUS = "Invalid_Plan"


class PlanStatus(str, Enum):
    """What a solve's outcome means for its use (module docstring)."""

    CONVERGED = "converged"
    CAPPED = "capped"
    FAILED = "failed"
    INVALID = "invalid"

    @classmethod
    def of(cls, raw_status: str) -> PlanStatus:
        """Classify an IPOPT `return_status`."""
        if raw_status in CONVERGED_STATUSES:
            return cls.CONVERGED
        if raw_status in CAPPED_STATUSES:
            return cls.CAPPED
        if raw_status == INVALID_RAW_STATUS:
            return cls.INVALID
        return cls.FAILED


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
HORIZON_WARM = {"mu_init": 1e-4, "mu_strategy": "monotone", "warm_start_init_point": "yes",
                "warm_start_bound_push": 1e-6, "warm_start_mult_bound_push": 1e-6,
                "warm_start_slack_bound_push": 1e-6, "nlp_scaling_method": "none"}
#: The first replan (or one after a failure) starts from the full-course plan, which was
#: solved with the roll dynamics: a larger barrier lets IPOPT move away from it (with the
#: warm settings 1 of 12 verona-like windows failed, with these none).
HORIZON_COLD = {"mu_init": 1e-2, "mu_strategy": "monotone", "nlp_scaling_method": "none"}


#: Cap on the adaptive barrier parameter (IPOPT's default 1e5) of the 1D model. Measured
#: with the issue-18 rider (bench/RESULTS.md, 2026-12-01): the adaptive update let the
#: barrier wander up and took 214 iterations on a 3.9 km climb at half the mesh spacing
#: (29 with the cap), 284 on rovereto-like at half spacing (38), and on a 9 km hilly
#: route converged to a plan that failed its verification (63 iterations, verified, with).
MU_MAX_1D = 0.1


def full_course_options(*, max_iter: int, max_cpu_time_s: float, tol: float,
                        bound_push: float, acceptable_tol: float | None = None,
                        mu_max: float | None = None) -> dict[str, Any]:
    """IPOPT options of the full-course OCP (`ocp.solve_plan`).

    `bound_push` (= `bound_frac`): how far the initial point is moved inside its bounds;
    IPOPT's default 1e-2 first (1e-4 took 116 instead of 75 iterations on verona-like 3D),
    1e-4 as a restart after an early failure (see `ocp`). `acceptable_tol`: IPOPT's
    acceptable level (default: IPOPT's own 1e-6 ... with 15 acceptable iterations).
    `mu_max`: cap of the adaptive barrier parameter (`MU_MAX_1D`); None: IPOPT's.
    """
    opts = {**_COMMON, "ipopt.max_iter": max_iter, "ipopt.max_cpu_time": max_cpu_time_s,
            "ipopt.tol": tol,
            # Measured on verona-like: adaptive 75 iterations (3D) / 43 (1D), monotone 239 / >400.
            "ipopt.mu_strategy": "adaptive",
            "ipopt.bound_push": bound_push, "ipopt.bound_frac": bound_push}
    if mu_max is not None:
        opts["ipopt.mu_max"] = mu_max
    if acceptable_tol is not None:
        opts |= {"ipopt.acceptable_tol": acceptable_tol, "ipopt.acceptable_iter": 5}
    return opts


def horizon_options(*, max_iter: int, max_wall_time_s: float, tol: float,
                    acceptable_iter: int, start: dict[str, Any]) -> dict[str, Any]:
    """IPOPT options of one horizon attempt (`start`: `HORIZON_WARM` or `HORIZON_COLD`)."""
    return {**_COMMON, "ipopt.max_iter": max_iter, "ipopt.tol": tol,
            "ipopt.acceptable_tol": 10 * tol, "ipopt.acceptable_iter": acceptable_iter,
            "ipopt.max_wall_time": max(max_wall_time_s, 1e-3),
            **{f"ipopt.{k}": v for k, v in start.items()}}
