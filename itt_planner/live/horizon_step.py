"""One horizon replan: the receding-horizon solve from the rider, or the fallback.

`HorizonStep` holds the engine's horizon planner (`ocp.horizon.HorizonPlanner`, whose
`HorizonSettings` own the horizon's length) and what the last replans left: the last
good solution, the solver status, iterations and solve time the advice reports, and the
failures in a row. A failed, raising or overrunning solve never reaches the rider: the
last good solution, shifted to the current `s`, stays in force as a fallback (before any
good solve, the full-course plan over the horizon serves).

A rider who stands (slower than `STANDING_MPS`, e.g. at a pause) is not replanned every
period: the horizon's NLP starts from the same clipped 1 m/s, at the same place, with
the power meter's 0 W, so each solve repeats the last (on the Zwift Bologna ride: 224
replans over a 220 s stop, every one advising the same 158 W launch; bench/RESULTS.md,
2026-12-02). After a good solve from a standing rider, the advice holds that solution
(status `HELD_STANDING`, no iterations, not a fallback, counted `horizon_holds_standing`;
moved to start where the rider stands) while the rider stands within `_HOLD_M` of where
it was solved, the power measured within `_HOLD_W` of what it was then (a rider pushing
off from a standstill is replanned), for at most `_HOLD_S` of the ride clock (the W' a
stop gives back is planned with again at least that often), and only while it is the
last good solution of the same planner (a re-solved plan, a CP refit or advice on the
plan end the hold). The rider rolling off is replanned at once.

Determinism: IPOPT's iterates do not depend on the wall clock, but the measured solve
time and an overrun check against it do. `deterministic` reports `solve_time_s = 0.0`,
declares no overruns (the planner's own iteration cap is the budget); the measured
times are still collected in `solve_times_s` (never published) for benchmarks.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
import time
from collections import Counter
from typing import TYPE_CHECKING

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.model.rider import Rider
from itt_planner.model.state import RiderState
from itt_planner.ocp.horizon_cut import Solution, from_plan
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import PlanStatus

if TYPE_CHECKING:
    from itt_planner.ocp.horizon import HorizonPlanner
    from itt_planner.ocp.horizon_settings import HorizonSolution

log = logging.getLogger(__name__)

#: Solver status of advice that holds the last solve for a standing rider.
HELD_STANDING = "held_standing"
#: Slower than this the rider stands: the horizon starts from this speed anyway
#: (`HorizonWindow.initial_state` clips the speed up to 1 m/s).
STANDING_MPS = 1.0
#: A standing rider within this of the held solve's start is at the same place (the
#: estimate drifts a little while standing).
_HOLD_M = 5.0
#: ... with the measured power within this of the held solve's (the NLP starts from it).
_HOLD_W = 10.0
#: A hold lasts at most this long (ride clock), so the W' a stop gives back is planned with.
_HOLD_S = 30.0


class HorizonStep:
    """The horizon planner and the bookkeeping of its solves (module docstring).

    Args:
        course: the course.
        planner: the horizon planner.
        max_solve_time_s, deterministic, line_gate_m: `EngineSettings`.
        lock: the engine's lock, which guards the last good solution (the on-plan
            advice and the shortfall detector use it outside the solve).
        stats: the engine's counters (solves, failures, overruns, fallbacks).
    """

    def __init__(self, course: Course, planner: HorizonPlanner, *, max_solve_time_s: float,
                 deterministic: bool, line_gate_m: float, lock: threading.Lock,
                 stats: Counter[str]) -> None:
        self.course = course
        self.planner = planner
        self.max_solve_time_s = max_solve_time_s
        self.deterministic = deterministic
        self.line_gate_m = line_gate_m
        self._lock = lock
        self._stats = stats
        #: The last good solution (set under the engine's lock).
        self.last_good: Solution | None = None
        self.status = "none"
        self.iterations = 0
        self.solve_time_s = 0.0
        self.consecutive_failures = 0
        #: Measured wall-clock solve times (s), for benchmarks; never published.
        self.solve_times_s: list[float] = []
        #: The good solve from a standing rider the advice may hold, with its planner
        #: (module docstring).
        self._held: tuple[Solution, HorizonPlanner] | None = None

    @property
    def horizon_m(self) -> float:
        """The horizon's length: the planner's."""
        return self.planner.settings.horizon_m

    def rebuild(self, rider: Rider, plan: Plan) -> None:
        """A new planner for the rider in use (CP refitted) and the plan in force
        (re-solved); a new HorizonPlanner costs tens of ms: fine once per event."""
        from itt_planner.ocp.horizon import HorizonPlanner  # noqa: PLC0415  (CasADi)

        old = self.planner
        self.planner = HorizonPlanner(self.course, rider, plan, conditions=old.conditions,
                                      settings=old.settings)

    def report(self, status: str) -> None:
        """Advice not from a solve (on the plan, finished): no iterations, no time."""
        self.status, self.iterations, self.solve_time_s = status, 0, 0.0

    def from_plan(self, plan: Plan, state: RiderState, w_prime_max_j: float) -> Solution:
        """The full-course plan over the horizon: the fallback before any good solve."""
        return from_plan(plan, self.course, state, self.horizon_m, w_prime_max_j)

    def solve(self, state: RiderState, start: RiderState, plan: Plan,
              w_prime_max_j: float) -> tuple[Solution, bool]:
        """Solve the horizon from `start` (`on_line(state)`): the solution and whether
        it is a fallback (the last good one, or the plan's when that has run out). A
        rider who stands is held on the last solve instead (module docstring)."""
        held = self._hold(state)
        if held is not None:
            self._stats["horizon_holds_standing"] += 1
            self.status, self.iterations, self.solve_time_s = HELD_STANDING, 0, 0.0
            return held, False
        t0 = time.perf_counter()
        try:
            sol: HorizonSolution | None = self.planner.solve(start)
            error = ""
        except Exception as err:  # the planner must never take the engine down
            log.exception("engine: horizon solve raised at s=%.0f m", state.s_m)
            sol, error = None, f"{type(err).__name__}: {err}"
        elapsed = time.perf_counter() - t0
        self.solve_times_s.append(elapsed)
        self._stats["solves"] += 1
        self.solve_time_s = 0.0 if self.deterministic else elapsed
        self.status = sol.status if sol is not None else "exception"
        self.iterations = sol.iterations if sol is not None else 0
        overrun = not self.deterministic and elapsed > self.max_solve_time_s
        if sol is not None and sol.success and not overrun:
            self.consecutive_failures = 0
            if sol.outcome is not PlanStatus.CONVERGED:
                self._stats["unconverged_solves"] += 1
            good = Solution(state, sol.s_m, sol.t_s, sol.power_w, sol.v_mps, sol.n_m,
                            sol.w_prime_j, sol.predicted_finish_s, sol.w_prime_finish_j)
            with self._lock:
                self.last_good = good
            self._held = (good, self.planner) if state.speed_mps < STANDING_MPS else None
            return good, False
        self.consecutive_failures += 1
        self._held = None
        if overrun:
            self._stats["overruns"] += 1
            self.status = f"overrun ({self.status})"
        elif sol is None:
            self._stats["exceptions"] += 1
            self.status = f"exception ({error})"
        else:
            self._stats["failures"] += 1
        self._stats["fallbacks"] += 1
        log.warning("engine: replan at s=%.0f m failed (%s); last good advice stays",
                    state.s_m, self.status)
        with self._lock:
            last = self.last_good
        if last is None or last.s_m[-1] <= state.s_m + 1.0:
            last = self.from_plan(plan, state, w_prime_max_j)
        return last, True

    def _hold(self, state: RiderState) -> Solution | None:
        """The solution to hold for a standing rider (module docstring), else None."""
        if self._held is None:
            return None
        good, planner = self._held
        with self._lock:
            last = self.last_good
        shift = state.s_m - float(good.s_m[0])
        if (good is last and planner is self.planner and state.speed_mps < STANDING_MPS
                and abs(shift) <= _HOLD_M
                and abs(state.power_w - good.state.power_w) <= _HOLD_W
                and state.elapsed_s - good.state.elapsed_s < _HOLD_S):
            # Moved to start where the rider stands, as a solve from there would: the
            # rider has not ridden into it (cut further along, its ramp from the measured
            # 0 W up to the launch power would be half done). Its time is the solve's:
            # the advice's finish projection counts the time stood since.
            return dataclasses.replace(good, s_m=good.s_m + shift)
        self._held = None
        return None

    def on_line(self, state: RiderState, plan: Plan) -> RiderState:
        """The state the horizon plans from: on the advised line (its offset and
        heading) unless the lateral estimate is more than `line_gate_m` off it.

        Why: the rider steers along the advised line to within a few decimetres (the
        virtual rider 0.3 m RMS), while a bike GPS places it to 2-3 m across the road.
        Planning from the estimated offset drew every new line from a noisy point, which
        the rider then followed: in the closed loop the horizon-led stretches ran 1-2.5 m
        RMS off the plan's line and lost up to 7 s per km on the technical descent of
        verona-like (bench/RESULTS.md). A rider really off the line (more than the gate)
        is planned from where the GPS puts it.
        """
        gate = self.line_gate_m
        with self._lock:
            good = self.last_good
        if good is None or not good.s_m[0] <= state.s_m <= good.s_m[-1] or len(good.s_m) < 3:
            s_line, n_line = plan.s_m, plan.n_m
        else:
            s_line, n_line = good.s_m, good.n_m
        n = float(np.interp(state.s_m, s_line, n_line))
        if gate <= 0 or not abs(state.n_m - n) <= gate:
            return state
        dn_ds = float(np.interp(state.s_m, s_line, np.gradient(n_line, s_line)))
        one_nk = 1.0 - n * float(self.course.at("kappa_per_m", state.s_m))
        heading = float(self.course.at("theta_rad", state.s_m)) + math.atan2(dn_ds, one_nk)
        return dataclasses.replace(state, n_m=n, heading_rad=heading)
