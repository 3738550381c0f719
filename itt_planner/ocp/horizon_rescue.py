"""The receding horizon's rescue after both exact attempts failed: continuation in E9's switch.

Why the exact attempts fail near critical power, and why the smoothed switch is solved,
polished and, failing the polish, advised with the exact W': `horizon` (module docstring,
"Rescue by continuation"). `HorizonRescue` owns the smoothed NLP (same layout and
parameters as the exact one, plus the transcription's acceleration bound), its solver, the
polish solver over the exact NLP, and the exact model's integrator that recomputes W'.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Sequence

import casadi as ca
import numpy as np

from itt_planner.model.dynamics import SpatialModel, build_3d_steady_lean, rk4_step
from itt_planner.model.params import ROAD
from itt_planner.ocp.horizon_settings import (
    BEYOND_LIMITS,
    SMOOTHED_FEASIBLE,
    SUBOPTIMAL_FEASIBLE,
    HorizonSettings,
)
from itt_planner.ocp.solver import PlanStatus, SolveResult, horizon_solver
from itt_planner.ocp.transcription import Transcription, transcribe

log = logging.getLogger(__name__)

#: (iterate, parameters, lower and upper simple bounds) -> whether it is valid advice
#: (`HorizonNlp.feasible`: dynamics, road, grip, W' >= 0).
Feasible = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], bool]


def usable(feasible: Feasible, res: SolveResult, p: np.ndarray, lbw: np.ndarray,
           ubw: np.ndarray) -> tuple[bool, list[str]]:
    """Whether a run's result is advice (`horizon` module docstring), and the status it
    adds: converged within the limits `feasible` checks; converged beyond them
    (`BEYOND_LIMITS`, not usable); stopped by the budget and feasible
    (`SUBOPTIMAL_FEASIBLE`). Every attempt of a replan is judged so, the polish too."""
    if res.converged:
        return (True, []) if feasible(res.w, p, lbw, ubw) else (False, [BEYOND_LIMITS])
    if res.iterations >= 1 and res.status is PlanStatus.CAPPED and feasible(res.w, p, lbw, ubw):
        return True, [SUBOPTIMAL_FEASIBLE]
    return False, []


def rescue_enabled(settings: HorizonSettings) -> bool:
    """Whether the settings ask for a rescue (a switch wider than the exact model's)."""
    return settings.rescue_sharpness_w > settings.sharpness_w


class HorizonRescue:
    """The rescue of one `HorizonPlanner`, built once with it; `solve` after a failure."""

    def __init__(self, model: SpatialModel, tr: Transcription, settings: HorizonSettings,
                 par: np.ndarray, feasible: Feasible) -> None:
        self._tr, self._par, self._feasible = tr, par, feasible
        self._ie = model.index("e_n")
        # The model with the E9 switch smoothed over `rescue_sharpness_w`, transcribed
        # alike (same decision vector and parameters, so its solution is a start of the
        # exact NLP as it is). With the acceleration bound: its solution may be advised
        # as it is, so it must not ride an integration artefact (a 1 km window up a 13 %
        # ramp "converged" to 28 m/s).
        smooth_model = build_3d_steady_lean(eps_wn=settings.eps_wn,
                                            sharpness_w=settings.rescue_sharpness_w)
        self._tr_smooth = transcribe(smooth_model, settings.n_intervals,
                                     substeps=settings.substeps, soft=True,
                                     slack_weight=settings.slack_weight, accel_bound=True)
        # `rescue_share` of the wall time: two thirds for the smooth solve (with
        # `max_iter` like every attempt), a third for the polish (`polish_max_iter`).
        wall = settings.rescue_share * settings.max_wall_time_s
        self.smooth = horizon_solver(self._tr_smooth, "horizon_smooth", warm=False,
                                     max_iter=settings.max_iter,
                                     max_wall_time_s=2.0 / 3.0 * wall, tol=settings.tol,
                                     acceptable_iter=settings.acceptable_iter)
        self.polish = horizon_solver(tr, "horizon_polish", warm=True,
                                     max_iter=settings.polish_max_iter,
                                     max_wall_time_s=wall / 3.0, tol=settings.tol,
                                     acceptable_iter=settings.acceptable_iter)
        self._step: ca.Function = rk4_step(model, settings.substeps)

    def solve(self, starts: Sequence[np.ndarray], p: np.ndarray, lbw: np.ndarray,
              ubw: np.ndarray) -> tuple[SolveResult | None, str, int]:
        """(a usable result or None, status, iterations) after the exact attempts failed.

        The smooth NLP from the first of the attempts' `starts` that converges; then the
        exact NLP from its solution (the polish). If the polish is not usable (converged
        beyond the limits `feasible` checks included), the smooth
        solution itself with W' recomputed by the exact model (`exact_w_prime`): the
        smoothing only changes E9, so the other states obey the exact dynamics as they
        are, and the exact W' is never below the smooth one (the softplus over-estimates
        max(P - CP, 0), so the smooth E9 drains at least as fast) - the iterate passes
        `feasible` like any other, and is advised with status `SMOOTHED_FEASIBLE`; its
        `status` (`PlanStatus`) is then the polish's, never `converged`. A usable result
        carries no multipliers (they are not the returned iterate's).
        """
        iterations, smooth = 0, None
        for w0 in starts:
            smooth = self.smooth.solve(w0, p, lbw, ubw)
            _log_error("smooth", smooth)
            iterations += smooth.iterations
            if smooth.converged:
                break
        if smooth is None or not smooth.converged:
            return None, f"rescue: {smooth.raw_status if smooth else 'no start'}", iterations
        lam_x0 = lam_g0 = None
        if smooth.lam_x is not None and smooth.lam_g is not None:
            # without the smooth NLP's acceleration rows (the exact NLP has none)
            accel = np.arange(len(smooth.lam_g))[self._tr_smooth.layout.accel_rows]
            lam_x0, lam_g0 = smooth.lam_x, np.delete(smooth.lam_g, accel)
        polish = self.polish.solve(smooth.w, p, lbw, ubw, lam_x0=lam_x0, lam_g0=lam_g0)
        _log_error("polish", polish)
        iterations += polish.iterations
        bare = dataclasses.replace(polish, lam_x=None, lam_g=None)
        ok, verdict = usable(self._feasible, polish, p, lbw, ubw)
        if ok:
            return bare, (verdict or [polish.raw_status])[-1], iterations
        w = self.exact_w_prime(smooth.w, p)
        if self._feasible(w, p, lbw, ubw):
            return dataclasses.replace(bare, w=w), SMOOTHED_FEASIBLE, iterations
        return (None, f"rescue: polish {polish.raw_status}, smooth solution not feasible",
                iterations)

    def exact_w_prime(self, w: np.ndarray, p: np.ndarray) -> np.ndarray:
        """`w` with W' (E_n) integrated interval by interval with the exact model's E9."""
        lay, ie = self._tr.layout, self._ie
        x, u, slacks = lay.split(w)
        n = lay.n_intervals
        road = p[: n * len(ROAD)].reshape(n, len(ROAD)).T  # as `Transcription.params` lays it
        x = x.copy()
        for k in range(n):
            xf = np.asarray(self._step(x[:, k], u[:, k], road[:, k], self._par)[0]).ravel()
            x[ie, k + 1] = min(float(xf[ie]), 1.0)
        return lay.join(x, u, slacks, float(w[-1]))


def _log_error(kind: str, res: SolveResult) -> None:
    if res.raw_status.startswith("error: "):
        log.warning("horizon rescue (%s) raised: %s", kind, res.raw_status)
