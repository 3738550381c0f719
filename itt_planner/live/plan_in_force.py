"""The plan in force: which full-course plan the engine follows, its version, when the
advice is the plan itself, and its re-solves from the rider's state.

Event-triggered replanning: while the rider's W' balance stays within `on_plan_band_j`
of the plan's at the same `s` (and the plan was solved for the CP in use), the advice IS
the plan from the rider's `s` (status "on_plan"): the plan is the optimum for what the
planner believes, and re-optimising it every second from a noisy state with the
horizon's reduced (steady-lean) model only added error - with a virtual rider that
follows the line, the ride replanned every second finished 0.7-1.9 % behind the optimum
where the plan followed blindly finished 0.3-0.6 % behind (bench/RESULTS.md). Once the
balance leaves the band (a hot start), or CP is refitted (a CP the rider does not have),
the horizon replans every period until the balance is back within half the band of the
plan in force, and the rest of the course is re-solved from the rider's state with the
full-course OCP in the background (`course_replan`); a converged re-solve becomes the
plan in force (`version` + 1), advised as such while the rider keeps to it and the
horizon's terminal treatment otherwise. A re-solve starts warm from the primal-dual
point of the plan in force when there is one (for the first plan, the point it was saved
or cached with: `course_replan.plan_point`); the counters say which way each started
(`course_replans_started_warm` / `_cold`) and how many warm runs converged at once
(`course_replans_warm_converged`; the others went on to the restarts), and which model
each solved (`course_replans_model_3d` / `_1d-line`, `course_replans_line_refused`,
`course_replans_line_after_3d_failed`: `resolve_model`).

Not thread-safe: the engine calls it with its locks held.
"""

from __future__ import annotations

import logging
from collections import Counter
from typing import TYPE_CHECKING

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.live.course_replan import CourseReplanner, CourseReplanSettings, start_from
from itt_planner.model.conditions import Conditions
from itt_planner.model.state import RiderState
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import PlanStatus

if TYPE_CHECKING:
    from itt_planner.ocp.horizon import HorizonPlanner

log = logging.getLogger(__name__)

#: Relative CP difference within which a plan counts as solved for the CP in use: what
#: a refit can tell (it found 417.4-422.3 W for a true 418 W), and what a hot start that
#: ignores the advice can fool the shortfall detector into (refits 0.3-1.5 % low).
_CP_TOL = 0.02


class PlanInForce:
    """The plan the engine follows and its re-solves (module docstring).

    Args:
        course: the course.
        plan: the first plan in force (version 0).
        cp_w: the CP `plan` was solved for.
        band_j: `EngineSettings.on_plan_band_j` (0: the advice is never the plan).
        conditions: what the re-solves assume.
        replan: when the rest of the course is re-solved.
        deterministic: adopt re-solves on the stamp clock (`course_replan`).
        stats: the engine's counters (re-solves asked, adopted, failed).
    """

    def __init__(self, course: Course, plan: Plan, cp_w: float, *, band_j: float,
                 conditions: Conditions, replan: CourseReplanSettings, deterministic: bool,
                 stats: Counter[str]) -> None:
        self.course = course
        self.plan = plan
        #: 0 for the first plan, +1 at every adoption.
        self.version = 0
        #: The CP the plan in force was solved for (a refit makes it not the rider's).
        self.cp_w = cp_w
        self.band_j = band_j
        self._stats = stats
        self._on_plan = band_j > 0
        self._replanner = CourseReplanner(course, conditions, replan, deterministic, plan=plan)
        #: Each adopted re-solve: where it started, what it solved and its predicted
        #: finish (s from its start), for benchmarks comparing re-solve models.
        self.adopted: list[dict[str, float | str | int]] = []
        if replan.period_s > 0 and self._replanner.cold_reason:
            log.info("engine: the first re-solve of the course will start from the plan's "
                     "primal point only: %s", self._replanner.cold_reason)

    @property
    def resolve_wait_s(self) -> float:
        """Wall-clock seconds spent waiting for re-solves (`CourseReplanner.waited_s`)."""
        return self._replanner.waited_s

    def fits_cp(self, cp_in_use_w: float) -> bool:
        """Whether the plan in force was solved for the CP in use, within `_CP_TOL`."""
        return abs(self.cp_w - cp_in_use_w) <= _CP_TOL * cp_in_use_w

    def follows(self, state: RiderState, cp_in_use_w: float) -> bool:
        """Whether the advice is the plan (module docstring): W' within the band (back
        within half of it after leaving it), and the plan in force solved for the CP in
        use (after a refit, only a plan re-solved with it)."""
        band = self.band_j
        if band <= 0 or not self.fits_cp(cp_in_use_w):
            self._on_plan = False
            return False
        dev = abs(state.w_prime_j - float(self.plan.at("w_prime_j", state.s_m)))
        self._on_plan = dev < (band if self._on_plan else 0.5 * band)
        return self._on_plan

    def request(self, stamp_s: float, planner: HorizonPlanner, state: RiderState) -> bool:
        """Ask for the rest of the course re-solved from `state` with the planner's
        rider (the CP in use) (`course_replan`; the replanner rate-limits). Returns
        whether a re-solve was started."""
        s0 = float(np.clip(state.s_m, 0.0, self.course.length_m - 1.0))
        start = start_from(planner, state, s0, self._replanner.settings.ocp)
        if not self._replanner.request(stamp_s, planner.rider, self.plan, start):
            return False
        self._stats["course_replans_asked"] += 1
        self._stats["course_replans_started_"
                    + ("warm" if self._replanner.last_warm else "cold")] += 1
        log.info("engine: off the plan at s=%.0f m (W' %.0f J, CP %.0f W): re-solving the "
                 "rest of the course", s0, state.w_prime_j, planner.rider.critical_power_w)
        return True

    def take(self, stamp_s: float) -> bool:
        """Make a finished re-solve of the rest of the course the plan in force (if it
        converged). Returns whether a new plan was adopted."""
        try:
            plan = self._replanner.take(stamp_s)
        except Exception:  # a failed solve never takes the engine down
            log.exception("engine: re-solving the rest of the course raised")
            self._stats["course_replan_failures"] += 1
            return False
        if plan is None:
            return False
        # Which model the re-solve solved (`resolve_model`): the 3D, or the 1D on the line
        # of the plan in force; and why the 1D was refused when it was asked for.
        resolved = plan.meta.get("resolve", {})
        self._stats[f"course_replans_model_{resolved.get('model', 'unknown')}"] += 1
        if resolved.get("after_3d_failed"):
            self._stats["course_replans_line_after_3d_failed"] += 1
            log.warning("engine: the re-solve from s=%.0f m is 1D on the line: %s",
                        plan.s_m[0], resolved["after_3d_failed"])
        if resolved.get("line_refused"):
            self._stats["course_replans_line_refused"] += 1
            log.info("engine: the re-solve from s=%.0f m is 3D: %s", plan.s_m[0],
                     resolved["line_refused"])
        first = (plan.meta.get("attempts") or [{}])[0]
        if first.get("strategy") == "warm" and first.get("outcome") == PlanStatus.CONVERGED:
            self._stats["course_replans_warm_converged"] += 1  # no restart needed
        if not plan.meta.get("success", False):
            log.warning("engine: re-solve of the course from s=%.0f m ended %s: the plan "
                        "in force stays", plan.s_m[0], plan.solver_status)
            self._stats["course_replan_failures"] += 1
            self._stats[f"course_replan_failed_{plan.solver_status}"] += 1  # which way
            return False
        self.plan = plan
        self.version += 1
        self.cp_w = float(plan.meta["rider"]["critical_power_w"])
        self._on_plan = True  # judged against the full band: the rider started on it
        self._stats["course_replans"] += 1
        self.adopted.append({"s_m": float(plan.s_m[0]), "model": resolved.get("model", "?"),
                             "rest_s": plan.finish_time_s, "iterations": plan.iterations,
                             "solve_time_s": plan.solve_time_s})
        if not plan.converged:
            self._stats["course_replans_unconverged"] += 1
        log.info("engine: new plan %d from s=%.0f m adopted (%s, %d iterations, %.1f s)",
                 self.version, plan.s_m[0], plan.solver_status, plan.iterations,
                 plan.solve_time_s)
        return True

    def close(self) -> None:
        """Stop the background re-solve (a solve still running is abandoned)."""
        self._replanner.close()
