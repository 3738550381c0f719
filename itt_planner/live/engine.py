"""The pacing engine: stamped inputs in, `Advice` out at the replan rate.

`PacingEngine` owns a `StateEstimator` and a receding-horizon planner
(`horizon.HorizonPlanner`). Inputs (`on_gps`, `on_speed`, `on_power`) may arrive on any
thread; `update(stamp_s)` replans when `replan_period_s` of STAMP time has passed since
the last advice. The engine is clocked only by message stamps, so a replay is
deterministic; the wall clock is read only to measure solve time.

Determinism: IPOPT's iterates do not depend on the wall clock, but the measured solve
time and an overrun check against it do. With `EngineSettings.deterministic` the advice
carries `solve_time_s = 0.0`, overruns are not declared (the planner's own iteration
cap is the budget) and diagnostics omit wall times, so two replays of one log give
byte-identical advice and diagnostics. The measured times are still collected in
`PacingEngine.solve_times_s` (never published) for benchmarks.

Event-triggered replanning: while the rider's W' balance stays within
`on_plan_band_j` of the plan's at the same `s` (and the plan was solved for the CP in
use), the advice IS the plan from the rider's `s` (status "on_plan"): the plan is
the optimum for what the planner believes, and re-optimising it every second from a
noisy state with the horizon's reduced (steady-lean) model only added error - with a
virtual rider that follows the line, the ride replanned every second finished 0.7-1.9 %
behind the optimum where the plan followed blindly finished 0.3-0.6 % behind
(bench/RESULTS.md).
Once the balance leaves the band (a hot start), or CP is refitted (a CP the rider
does not have), the horizon replans every period until the balance is back within half
the band of the plan in force, and the rest of the course is re-solved from the
rider's state with the full-course OCP in the background (`course_replan`, at most
every `course_replan.period_s`); that new plan becomes the plan in force, advised as
such while the rider keeps to it and the horizon's terminal treatment otherwise.

The engine is the one owner of the belief it plans with: the CP in use and the W' model
(`cp_monitor.CpMonitor`, which revises CP both ways from the power the rider delivers)
and the full-course plan in force with its version (`plan_version`, +1 at every
adoption). Each `Advice` carries both, and its target power is shaped into what a rider
can follow, with a pedal / coast / brake / climb cue (`advice_shaping`). `counts` sums
up what was not used silently (fallbacks, failed re-solves, refits).

A failed, raising or overrunning solve never reaches the rider: the last good advice,
shifted to the current `s`, stays in force with `fallback=True` (before any good solve,
the full-course plan over the horizon serves), and a diagnostic says so.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from itt_planner.live.advice import Advice, Cue, Diagnostic
from itt_planner.live.advice_shaping import AdviceShaper, ShapingSettings
from itt_planner.model.conditions import Conditions
from itt_planner.course.geometry import Course
from itt_planner.live.course_replan import CourseReplanner, CourseReplanSettings, start_from
from itt_planner.live.cp_monitor import CpMonitor, CpMonitorSettings, Refit
from itt_planner.live.health import (
    CONVERGED, EngineCounts, input_diagnostics, solver_diagnostic,
)
from itt_planner.live.estimate import EstimatorSettings, StateEstimator
from itt_planner.ocp.horizon_cut import Solution, advice_fields, finished_fields, from_plan
from itt_planner.ocp.plan import Plan
from itt_planner.model.rider import Rider
from itt_planner.live.samples import GpsFix, PowerReading, Sample, WheelSpeed
from itt_planner.model.state import RiderState

if TYPE_CHECKING:
    from itt_planner.ocp.horizon import HorizonPlanner
    from itt_planner.ocp.horizon_settings import HorizonSolution

log = logging.getLogger(__name__)

#: Solver status of advice that is the full-course plan (the rider is on it).
ON_PLAN = "on_plan"
#: Relative CP difference within which a plan counts as solved for the CP in use: what
#: a refit can tell (it found 417.4-422.3 W for a true 418 W), and what a hot start that
#: ignores the advice can fool the shortfall detector into (refits 0.3-1.5 % low).
_CP_TOL = 0.02
#: Closer than this to the finish there is nothing left to plan.
_FINISHED_M = 5.0


@dataclass(frozen=True)
class EngineSettings:
    """Rates, budgets and freshness limits of the engine.

    Attributes:
        replan_period_s: stamp time between two advices.
        horizon_m: length of the receding horizon (used when the engine builds its
            planner; a planner passed in keeps its own).
        max_solve_time_s: a solve taking longer is an overrun: its result is dropped
            and the last good advice stays (ignored when `deterministic`).
        stale_after_s: an input topic silent for longer is reported STALE.
        failures_for_error: consecutive failed solves that turn the solver
            diagnostic from WARN to ERROR.
        deterministic: publish `solve_time_s = 0.0` and never judge overruns by the
            wall clock, for byte-identical replays (module docstring).
        estimator: settings of the state estimator.
        cp_monitor: when CP is refitted, down or up (`cp_monitor`).
        shaping: how the planner's power becomes a target and a cue (`advice_shaping`).
        on_plan_band_j: W' deviation from the plan within which the advice is the plan
            (module docstring; 0 replans always). 2 kJ: about three times the balance's
            error against the truth in the closed-loop tests (0.1-0.7 kJ).
        course_replan: when the rest of the course is re-solved off the plan
            (`course_replan`; period 0: never).
        line_gate_m: the horizon plans from the advised line unless the lateral
            estimate is further off it than this (`_on_line`; 0: from the estimate).
            5 m: twice the bike GPS's lateral error (3 m per axis, partly averaged).
    """

    replan_period_s: float = 1.0
    horizon_m: float = 1000.0
    max_solve_time_s: float = 1.0
    stale_after_s: float = 3.0
    failures_for_error: int = 3
    deterministic: bool = False
    estimator: EstimatorSettings = field(default_factory=EstimatorSettings)
    cp_monitor: CpMonitorSettings = field(default_factory=CpMonitorSettings)
    shaping: ShapingSettings = field(default_factory=ShapingSettings)
    on_plan_band_j: float = 2000.0
    course_replan: CourseReplanSettings = field(default_factory=CourseReplanSettings)
    line_gate_m: float = 5.0


class PacingEngine:
    """Inputs in, advice out (see the module docstring).

    Args:
        course, rider, plan: the course, the rider the planner believes in, and the
            full-course plan (terminal treatment of the horizon, first fallback).
        conditions: road grip and wind the planner assumes.
        settings: engine settings.
        planner: a prebuilt `HorizonPlanner` (building one compiles CasADi Functions;
            share it between engines on one course); built here when None.
    """

    def __init__(self, course: Course, rider: Rider, plan: Plan, *,
                 conditions: Conditions = Conditions(),
                 settings: EngineSettings = EngineSettings(),
                 planner: HorizonPlanner | None = None) -> None:
        if planner is None:
            from itt_planner.ocp.horizon import HorizonPlanner
            from itt_planner.ocp.horizon_settings import HorizonSettings

            planner = HorizonPlanner(course, rider, plan, conditions=conditions,
                                     settings=HorizonSettings(horizon_m=settings.horizon_m))
        self.course = course
        self.rider = rider
        self.plan = plan
        self.settings = settings
        self.planner = planner
        self._estimator = StateEstimator(course, rider, settings.estimator)
        self._cp = CpMonitor(rider, self._estimator, settings.cp_monitor)
        self._shaper = AdviceShaper(course, rider.power_rate_max_wps, settings.shaping)
        #: Version of the plan in force: 0 for `plan`, +1 at every adoption.
        self.plan_version = 0
        self._lock = threading.Lock()  # estimator + bookkeeping
        self._solve_lock = threading.Lock()  # one solve at a time
        self._last_advice_stamp: float | None = None
        self._last_good: Solution | None = None
        self._last_status = "none"
        self._last_iterations = 0
        self._last_solve_time = 0.0
        self._consecutive_failures = 0
        self._stats: Counter[str] = Counter()
        self._reported_rejects: dict[str, int] = {}
        self._last_input: dict[str, float] = {}
        #: Measured wall-clock solve times (s), for benchmarks; never published.
        self.solve_times_s: list[float] = []
        #: The target power published last (what the rider was told to hold).
        self._last_target_w: float | None = None
        self._on_plan = settings.on_plan_band_j > 0
        #: The CP the plan in force was solved for (a refit makes it not the rider's).
        self._plan_cp_w = rider.critical_power_w
        #: The horizon planner still holds an older rider or plan (rebuilt before a solve).
        self._planner_stale = False
        self._course_replanner = CourseReplanner(course, planner.conditions,
                                                 settings.course_replan, settings.deterministic)

    # ---- inputs (any thread; never raise) -----------------------------------------------------
    def on_gps(self, fix: GpsFix) -> None:
        self._input("gps", fix, self._estimator.on_gps)

    def on_speed(self, sample: WheelSpeed) -> None:
        self._input("speed", sample, self._estimator.on_speed)

    def on_power(self, sample: PowerReading) -> None:
        self._input("power", sample, self._estimator.on_power)

    def on_sample(self, sample: Sample) -> None:
        """Any input sample, dispatched by its type (for loops over a recorded stream)."""
        if isinstance(sample, GpsFix):
            self.on_gps(sample)
        elif isinstance(sample, WheelSpeed):
            self.on_speed(sample)
        else:
            self.on_power(sample)

    def _input(self, topic: str, sample: Any, handler: Any) -> None:
        with self._lock:
            try:
                accepted = handler(sample)
            except Exception:  # a live path never dies on one message
                log.exception("engine: %s sample %s crashed the estimator", topic, sample)
                self._estimator.counters[f"{topic}_exception"] += 1
                return
            if accepted:
                self._last_input[topic] = sample.stamp_s

    # ---- queries --------------------------------------------------------------------------
    @property
    def state(self) -> RiderState | None:
        """The state at the last input's stamp (None before the first GPS fix)."""
        with self._lock:
            stamps = [*self._last_input.values(), self._estimator.stamp_s]
            known = [s for s in stamps if s is not None]
            return self._estimator.state(max(known)) if known else None

    @property
    def counters(self) -> dict[str, int]:
        """Estimator rejections and engine events (solves, failures, fallbacks, refits)."""
        with self._lock:
            return {**self._estimator.counters, **self._stats}

    @property
    def counts(self) -> EngineCounts:
        """The engine's events and the belief in force (`EngineCounts`), read-only."""
        with self._lock:
            st = self._stats
            return EngineCounts(
                advice=st["advice"], fallbacks=st["fallbacks"], solves=st["solves"],
                solve_failures=st["failures"] + st["overruns"] + st["exceptions"],
                unconverged_solves=st["unconverged_solves"],
                course_replans_asked=st["course_replans_asked"],
                course_replans_adopted=st["course_replans"],
                course_replan_failures=st["course_replan_failures"],
                refits_up=st["cp_refits_up"], refits_down=st["cp_refits_down"],
                cp_in_use_w=self._cp.cp_in_use_w, plan_version=self.plan_version,
                plan_status=self.plan.solver_status,
                plan_converged=self.plan.converged)

    @property
    def critical_power_w(self) -> float:
        """The CP in use: the believed one until a refit revises it."""
        with self._lock:
            return self._cp.cp_in_use_w

    @property
    def refits(self) -> list[Refit]:
        """Every CP refit so far with its evidence."""
        with self._lock:
            return list(self._cp.refits)

    # ---- the replan ---------------------------------------------------------------------------
    def update(self, stamp_s: float) -> Advice | None:
        """Replan if `replan_period_s` of stamp time has passed since the last advice.

        Returns None when no advice is due or before the first usable state.
        """
        with self._lock:
            last = self._last_advice_stamp
            if last is not None and stamp_s - last < self.settings.replan_period_s - 1e-9:
                return None
            state = self._estimator.state(stamp_s)
            if state is None:
                return None
            self._last_advice_stamp = stamp_s
            if self._last_target_w is not None and self._refit(stamp_s, state):
                state = self._estimator.state(stamp_s) or state
                self._planner_stale = True
            self._adopt_course_plan(stamp_s)
            on_plan = (self._follows_plan(state)
                       and self.course.length_m - state.s_m > _FINISHED_M)
            # Left the plan: W' out of the band (when there is one), or a plan for a CP
            # the rider does not have. Then the rest of the course is re-solved too.
            left_plan = not on_plan and (self.settings.on_plan_band_j > 0
                                         or not self._plan_fits_cp())
            if on_plan:
                self._consecutive_failures = 0
                good = self._from_plan(state)
                self._last_good = good  # the shortfall detector compares against it
                self._last_status, self._last_iterations, self._last_solve_time = (
                    ON_PLAN, 0, 0.0)
        if on_plan:
            return self._advice(stamp_s, state, good, fallback=False)
        with self._solve_lock:
            if self._planner_stale:  # the inputs stay unlocked while it is rebuilt
                self._replace_planner()
            start = self._on_line(state)
            if left_plan:
                self._request_course_plan(stamp_s, start)
            return self._replan(stamp_s, state, start)

    def _follows_plan(self, state: RiderState) -> bool:
        """Whether the advice is the plan (module docstring): W' within the band (back
        within half of it after leaving it), and the plan in force solved for the CP in
        use (after a refit, only a plan re-solved with it). Called with `self._lock`
        held."""
        band = self.settings.on_plan_band_j
        if band <= 0 or not self._plan_fits_cp():
            self._on_plan = False
            return False
        dev = abs(state.w_prime_j - float(self.plan.at("w_prime_j", state.s_m)))
        self._on_plan = dev < (band if self._on_plan else 0.5 * band)
        return self._on_plan

    def _plan_fits_cp(self) -> bool:
        """Whether the plan in force was solved for the CP in use, within `_CP_TOL`.
        Called with `self._lock` held."""
        cp = self._cp.cp_in_use_w
        return abs(self._plan_cp_w - cp) <= _CP_TOL * cp

    def _replace_planner(self) -> None:
        """Rebuild the horizon planner for the rider in use (CP refitted) and the plan in
        force (re-solved); a new HorizonPlanner costs tens of ms: fine once per event.
        Called with `self._solve_lock` held."""
        from itt_planner.ocp.horizon import HorizonPlanner

        with self._lock:
            rider = dataclasses.replace(self.rider, critical_power_w=self._cp.cp_in_use_w)
            plan = self.plan
            self._planner_stale = False
        old = self.planner
        self.planner = HorizonPlanner(self.course, rider, plan, conditions=old.conditions,
                                      settings=old.settings)

    def _request_course_plan(self, stamp_s: float, state: RiderState) -> None:
        """Ask for the rest of the course re-solved from `state` (`course_replan`; the
        replanner rate-limits). Called with `self._solve_lock` held, the planner current."""
        s0 = float(np.clip(state.s_m, 0.0, self.course.length_m - 1.0))
        start = start_from(self.planner, state, s0)
        if self._course_replanner.request(stamp_s, self.planner.rider, self.plan, start):
            self._stats["course_replans_asked"] += 1
            log.info("engine: off the plan at s=%.0f m (W' %.0f J, CP %.0f W): re-solving the "
                     "rest of the course", s0, state.w_prime_j, self.planner.rider.critical_power_w)

    def _adopt_course_plan(self, stamp_s: float) -> None:
        """Make a finished re-solve of the rest of the course the plan in force (if it
        converged). Called with `self._lock` held."""
        try:
            plan = self._course_replanner.take(stamp_s)
        except Exception:  # a failed solve never takes the engine down
            log.exception("engine: re-solving the rest of the course raised")
            self._stats["course_replan_failures"] += 1
            return
        if plan is None:
            return
        if not plan.meta.get("success", False):
            log.warning("engine: re-solve of the course from s=%.0f m ended %s: the plan "
                        "in force stays", plan.s_m[0], plan.solver_status)
            self._stats["course_replan_failures"] += 1
            return
        self.plan = plan
        self.plan_version += 1
        self._plan_cp_w = float(plan.meta["rider"]["critical_power_w"])
        self._planner_stale = True
        self._on_plan = True  # judged against the full band: the rider started on it
        self._stats["course_replans"] += 1
        if plan.solver_status not in CONVERGED:
            self._stats["course_replans_unconverged"] += 1
        log.info("engine: new plan %d from s=%.0f m adopted (%s, %d iterations, %.1f s)",
                 self.plan_version, plan.s_m[0], plan.solver_status, plan.iterations,
                 plan.solve_time_s)

    def close(self) -> None:
        """Stop the background re-solve (a solve still running is abandoned)."""
        self._course_replanner.close()

    def _refit(self, stamp_s: float, state: RiderState) -> bool:
        """Let the CP monitor judge the last target against the power delivered
        (`cp_monitor`); after a refit the planner is rebuilt with the new CP
        (`_replace_planner`) and the plan, solved for another CP, is no longer followed
        (`_follows_plan`) until the rest of the course is re-solved with it. Called with
        `self._lock` held. Returns whether CP was refitted."""
        assert self._last_target_w is not None
        refit = self._cp.observe(stamp_s, state, self._last_target_w)
        if refit is None:
            return False
        self._stats["cp_refits"] += 1
        self._stats[f"cp_refits_{refit.direction}"] += 1
        return True

    def _replan(self, stamp_s: float, state: RiderState, start: RiderState) -> Advice:
        """Solve the horizon from `start` (`_on_line(state)`); the advice carries the
        estimate `state`."""
        if self.course.length_m - state.s_m <= _FINISHED_M:
            return self._finished(stamp_s, state)
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
        self._last_solve_time = 0.0 if self.settings.deterministic else elapsed
        self._last_status = sol.status if sol is not None else "exception"
        self._last_iterations = sol.iterations if sol is not None else 0
        overrun = (not self.settings.deterministic
                   and elapsed > self.settings.max_solve_time_s)
        if sol is not None and sol.success and not overrun:
            self._consecutive_failures = 0
            if sol.status not in CONVERGED:
                self._stats["unconverged_solves"] += 1
            good = Solution(state, sol.s_m, sol.t_s, sol.power_w, sol.v_mps, sol.n_m,
                            sol.w_prime_j, sol.predicted_finish_s, sol.w_prime_finish_j)
            with self._lock:
                self._last_good = good
            return self._advice(stamp_s, state, good, fallback=False)
        self._consecutive_failures += 1
        if overrun:
            self._stats["overruns"] += 1
            self._last_status = f"overrun ({self._last_status})"
        elif sol is None:
            self._stats["exceptions"] += 1
            self._last_status = f"exception ({error})"
        else:
            self._stats["failures"] += 1
        self._stats["fallbacks"] += 1
        log.warning("engine: replan at s=%.0f m failed (%s); last good advice stays",
                    state.s_m, self._last_status)
        with self._lock:
            good = self._last_good
        if good is None or good.s_m[-1] <= state.s_m + 1.0:
            good = self._from_plan(state)
        return self._advice(stamp_s, state, good, fallback=True)

    def _on_line(self, state: RiderState) -> RiderState:
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
        gate = self.settings.line_gate_m
        with self._lock:
            good = self._last_good
        if good is None or not good.s_m[0] <= state.s_m <= good.s_m[-1] or len(good.s_m) < 3:
            s_line, n_line = self.plan.s_m, self.plan.n_m
        else:
            s_line, n_line = good.s_m, good.n_m
        n = float(np.interp(state.s_m, s_line, n_line))
        if gate <= 0 or not abs(state.n_m - n) <= gate:
            return state
        dn_ds = float(np.interp(state.s_m, s_line, np.gradient(n_line, s_line)))
        one_nk = 1.0 - n * float(self.course.at("kappa_per_m", state.s_m))
        heading = float(self.course.at("theta_rad", state.s_m)) + math.atan2(dn_ds, one_nk)
        return dataclasses.replace(state, n_m=n, heading_rad=heading)

    def _from_plan(self, state: RiderState) -> Solution:
        """The full-course plan over the horizon: the fallback before any good solve."""
        return from_plan(self.plan, self.course, state, self.settings.horizon_m,
                         self.rider.w_prime_j)

    def _advice(self, stamp_s: float, state: RiderState, good: Solution, *,
                fallback: bool) -> Advice:
        """Advice from a solution cut at the rider's `s` (`horizon_cut`), its target and
        cue shaped into what a rider can follow (`advice_shaping`: node 0 holds the
        measured power, the OCP's initial state; the target is what the solution rides
        from there on)."""
        fields = advice_fields(self.course, state, good)
        with self._lock:
            shaped = self._shaper.shape(stamp_s, state.s_m, state.speed_mps,
                                        self._cp.cp_in_use_w, fields["horizon_s_m"],
                                        fields["horizon_power_w"], fields["horizon_speed_mps"])
            self._last_target_w = shaped["target_power_w"]
            self._stats["advice"] += 1
            cp, version = self._cp.cp_in_use_w, self.plan_version
        return Advice(stamp_s=stamp_s, state=state, **shaped, **fields,
                      solver_status=self._last_status, iterations=self._last_iterations,
                      solve_time_s=self._last_solve_time, fallback=fallback, cp_in_use_w=cp,
                      plan_version=version)

    def _finished(self, stamp_s: float, state: RiderState) -> Advice:
        """Past the finish line: nothing to plan; the advice says so (coast, 0 W)."""
        self._last_status = "finished"
        self._last_iterations = 0
        self._last_solve_time = 0.0
        with self._lock:
            self._last_target_w = 0.0
            self._shaper.reset()
            self._stats["advice"] += 1
            cp, version = self._cp.cp_in_use_w, self.plan_version
        return Advice(stamp_s=stamp_s, state=state, target_power_w=0.0, cue=Cue.COAST,
                      **finished_fields(self.course, state), solver_status="finished",
                      iterations=0, solve_time_s=0.0, cp_in_use_w=cp, plan_version=version)

    # ---- diagnostics and persistence ------------------------------------------------------------
    def diagnostics(self, stamp_s: float) -> list[Diagnostic]:
        """Solver health, the CP belief, input freshness per topic, rejected inputs."""
        st = self.settings
        with self._lock:
            rejects = {k: v for k, v in self._estimator.counters.items()
                       if not k.endswith("_accepted")}
            last_input = dict(self._last_input)
            stats = dict(self._stats)
            rider_model = self._cp.diagnostic(stamp_s)
        solver = solver_diagnostic(
            stamp_s, self._last_status, self._last_status == ON_PLAN, self._last_iterations,
            self._consecutive_failures, st.failures_for_error, stats, self.plan_version,
            self.plan.solver_status, None if st.deterministic else self._last_solve_time)
        inputs = input_diagnostics(stamp_s, last_input, st.stale_after_s, rejects,
                                   self._reported_rejects)
        self._reported_rejects = rejects
        return [solver, rider_model, *inputs]

    def snapshot(self) -> dict[str, Any]:
        """W' balance, the CP in use, progress and the replan clock, JSON-serialisable."""
        with self._lock:
            return {"estimator": self._estimator.snapshot(),
                    "cp_in_use_w": self._cp.cp_in_use_w,
                    "last_advice_stamp_s": self._last_advice_stamp}

    def restore(self, snap: dict[str, Any]) -> None:
        """Resume after a node restart from `snapshot()` (a snapshot without
        `cp_in_use_w`, from before refits were saved, keeps the believed CP). The first
        target after it is not rate-limited.

        Raises:
            KeyError: a field of the snapshot is missing.
        """
        with self._lock:
            self._estimator.restore(snap["estimator"])
            self._estimator.use_critical_power(float(snap.get("cp_in_use_w",
                                                              self.rider.critical_power_w)))
            self._last_advice_stamp = snap["last_advice_stamp_s"]
            self._shaper.reset()
            self._last_target_w = None
