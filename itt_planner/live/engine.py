"""The pacing engine: stamped samples in, `Advice` out at the replan rate.

`PacingEngine` is the one owner of the belief it plans with: the W' model with the CP in use
(`wprime_balance.WPrimeBalance`, revised both ways by `cp_monitor.CpMonitor` from the power
the rider delivers) and the full-course plan in force with its version
(`plan_in_force.PlanInForce`, +1 at every adoption). Each `Advice` carries both, and its
target power is shaped into what a rider can follow, with a pedal / coast / brake / climb cue
(`advice_shaping`). `counts`: what was not used silently (fallbacks, failed re-solves, refits).

Samples (`on_sample`, any type with an estimator hook) may arrive on any thread;
`update(stamp_s)` replans when `replan_period_s` of STAMP time has passed since the last
advice. The engine is clocked only by message stamps, so a replay is deterministic; the wall
clock is read only to measure solve time (`horizon_step`; with `EngineSettings.deterministic`
the advice carries `solve_time_s = 0.0`, no overrun is declared and diagnostics omit wall
times, so two replays of one log give byte-identical advice and diagnostics).

At each replan the advice is the plan in force while the rider keeps to it (`plan_in_force`),
else a receding-horizon solve from the rider (`horizon_step`, which falls back to the last
good advice when a solve fails: `fallback=True` and a diagnostic say so).
"""

from __future__ import annotations

import dataclasses
import logging
import threading
from collections import Counter
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from itt_planner.course.geometry import Course
from itt_planner.live.advice import Advice, Cue, Diagnostic
from itt_planner.live.advice_shaping import AdviceShaper, ShapingSettings
from itt_planner.live.course_replan import CourseReplanSettings
from itt_planner.live.cp_monitor import CpMonitor, CpMonitorSettings, Refit
from itt_planner.live.estimate import StateEstimator
from itt_planner.live.estimator_settings import EstimatorSettings
from itt_planner.live.health import EngineCounts, input_diagnostics, solver_diagnostic
from itt_planner.live.horizon_step import HorizonStep
from itt_planner.live.plan_in_force import PlanInForce
from itt_planner.live.resolve_gate import ResolveGate
from itt_planner.live.samples import Sample
from itt_planner.live.wprime_balance import WPrimeBalance
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import Rider
from itt_planner.model.state import RiderState
from itt_planner.ocp.course_nlp import start_speed
from itt_planner.ocp.horizon_cut import Solution, advice_fields, finished_fields
from itt_planner.ocp.horizon_settings import HorizonSettings
from itt_planner.ocp.plan import Plan

if TYPE_CHECKING:
    from itt_planner.ocp.horizon import HorizonPlanner

log = logging.getLogger(__name__)

#: Solver status of advice that is the full-course plan (the rider is on it).
ON_PLAN = "on_plan"
#: Closer than this to the finish there is nothing left to plan.
_FINISHED_M = 5.0


@dataclass(frozen=True)
class EngineSettings:
    """Rates, budgets and freshness limits of the engine (the horizon's own settings,
    its length among them, are the planner's `HorizonSettings`).

    Attributes:
        replan_period_s: stamp time between two advices.
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
            (`plan_in_force`; 0 replans always). 2 kJ: about three times the balance's
            error against the truth in the closed-loop tests (0.1-0.7 kJ).
        course_replan: when the rest of the course is re-solved off the plan
            (`course_replan`; period 0: never).
        line_gate_m: the horizon plans from the advised line unless the lateral
            estimate is further off it than this (`HorizonStep.on_line`; 0: from the
            estimate). 5 m: twice the bike GPS's lateral error (3 m per axis, partly
            averaged).
    """

    replan_period_s: float = 1.0
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
    """Samples in, advice out (see the module docstring).

    Args:
        course, rider, plan: the course, the rider the planner believes in, and the
            full-course plan (terminal treatment of the horizon, first fallback).
        conditions: road grip and wind the planner assumes (when it is built here).
        settings: engine settings.
        planner: a prebuilt `HorizonPlanner` (building one compiles CasADi Functions;
            share it between engines on one course); built here when None ...
        horizon: ... with these settings (the default `HorizonSettings` when None).

    Raises:
        ValueError: both `planner` and `horizon` given (the planner has its settings).
    """

    def __init__(self, course: Course, rider: Rider, plan: Plan, *,
                 conditions: Conditions = Conditions(), settings: EngineSettings = EngineSettings(),
                 planner: HorizonPlanner | None = None, horizon: HorizonSettings | None = None
                 ) -> None:
        if planner is None:
            from itt_planner.ocp.horizon import HorizonPlanner  # noqa: PLC0415  (CasADi)

            planner = HorizonPlanner(course, rider, plan, conditions=conditions,
                                     settings=horizon or HorizonSettings())
        elif horizon is not None:
            raise ValueError("PacingEngine: pass a planner or its horizon settings, not both")
        self.course = course
        self.rider = rider
        self.settings = settings
        self._lock = threading.Lock()  # estimator + bookkeeping
        self._solve_lock = threading.Lock()  # one solve at a time
        self._stats: Counter[str] = Counter()
        est = settings.estimator
        self._balance = WPrimeBalance(rider, est.power_hold_s, est.wprime_model)
        self._estimator = StateEstimator(course, self._balance, est)
        self._cp = CpMonitor(rider, self._balance, settings.cp_monitor)
        self._shaper = AdviceShaper(course, rider.power_rate_max_wps, settings.shaping)
        self._plans = PlanInForce(course, plan, rider.critical_power_w,
                                  band_j=settings.on_plan_band_j, conditions=planner.conditions,
                                  replan=settings.course_replan,
                                  deterministic=settings.deterministic, stats=self._stats)
        #: When a re-solve may be asked for (back-off, stopped rider: `resolve_gate`).
        self._gate = ResolveGate(settings.course_replan, start_speed(
            rider, planner.conditions, settings.course_replan.ocp), self._stats)
        #: The horizon planner and its solves (`horizon_step`).
        self.horizon = HorizonStep(course, planner, max_solve_time_s=settings.max_solve_time_s,
                                   deterministic=settings.deterministic, lock=self._lock,
                                   line_gate_m=settings.line_gate_m, stats=self._stats)
        self._last_advice_stamp: float | None = None
        self._reported_rejects: dict[str, int] = {}
        self._last_input: dict[str, float] = {}
        #: The target power published last (what the rider was told to hold).
        self._last_target_w: float | None = None
        #: The horizon planner still holds an older rider or plan (rebuilt before a solve).
        self._planner_stale = False

    # ---- inputs (any thread; never raise) -----------------------------------------------------
    def on_sample(self, sample: Sample) -> None:
        """Any input sample, handled by the estimator's hook for its type."""
        with self._lock:
            try:
                sensor, hook = self._estimator.hook(sample)
                accepted = hook(sample)
            except Exception:  # a live path never dies on one message
                sensor = self._estimator.hooks.get(type(sample), (type(sample).__name__,))[0]
                log.exception("engine: %s sample %s crashed the estimator", sensor, sample)
                self._estimator.counters[f"{sensor}_exception"] += 1
                return
            if accepted:
                self._last_input[sensor] = sample.stamp_s

    # ---- queries --------------------------------------------------------------------------
    @property
    def state(self) -> RiderState | None:
        """The state at the last input's stamp (None before the first GPS fix)."""
        with self._lock:
            stamps = [*self._last_input.values(), self._estimator.stamp_s]
            known = [s for s in stamps if s is not None]
            return self._estimator.state(max(known)) if known else None

    @property
    def estimate(self) -> RiderState | None:
        """The estimate as the last sample left it, read without predicting it forward
        (so a view may ask after every sample without changing the filter)."""
        with self._lock:
            t = self._estimator.stamp_s
            return None if t is None else self._estimator.state(t)

    @property
    def plan(self) -> Plan:
        """The full-course plan in force."""
        return self._plans.plan

    @property
    def plan_version(self) -> int:
        """Version of the plan in force: 0 for the first plan, +1 at every adoption."""
        return self._plans.version

    @property
    def solve_times_s(self) -> list[float]:
        """Measured wall-clock horizon solve times (s), for benchmarks; never published."""
        return self.horizon.solve_times_s

    @property
    def plans(self) -> PlanInForce:
        """The plan in force and its re-solves (waits, adopted plans), for benchmarks."""
        return self._plans

    @property
    def counters(self) -> dict[str, int]:
        """Estimator rejections and engine events (solves, failures, fallbacks, refits)."""
        with self._lock:
            return {**self._estimator.counters, **self._stats, **self._cp.counts()}

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
                course_replans_backed_off=st["course_replans_backed_off"],
                course_replans_skipped_stopped=st["course_replans_skipped_stopped"],
                refits_up=st["cp_refits_up"], refits_down=st["cp_refits_down"],
                cp_in_use_w=self._balance.cp_w, plan_version=self._plans.version,
                plan_status=self._plans.plan.solver_status,
                plan_converged=self._plans.plan.converged)

    @property
    def critical_power_w(self) -> float:
        """The CP in use: the believed one until a refit revises it."""
        with self._lock:
            return self._balance.cp_w

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
        plans, horizon = self._plans, self.horizon
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
                self._gate.reset()
            if plans.take(stamp_s):
                self._planner_stale = True
                self._gate.adopted(stamp_s)
            cp = self._balance.cp_w
            on_plan = (plans.follows(state, cp)
                       and self.course.length_m - state.s_m > _FINISHED_M)
            # Left the plan: W' out of the band (when there is one), or a plan for a CP
            # the rider does not have. Then the rest of the course is re-solved too.
            left_plan = not on_plan and (self.settings.on_plan_band_j > 0
                                         or not plans.fits_cp(cp))
            (self._gate.on_plan if on_plan else self._gate.off_plan)(stamp_s)
            if on_plan:
                horizon.consecutive_failures = 0
                good = horizon.from_plan(plans.plan, state, self.rider.w_prime_j)
                horizon.last_good = good  # the shortfall detector compares against it
                horizon.report(ON_PLAN)
        if on_plan:
            return self._advice(stamp_s, state, good, fallback=False)
        with self._solve_lock:
            if self._planner_stale:  # the inputs stay unlocked while it is rebuilt
                self._replace_planner()
            start = horizon.on_line(state, plans.plan)
            if (left_plan and self._gate.allow(stamp_s, state.speed_mps, state.s_m,
                                               self.course.length_m - state.s_m)
                    and plans.request(stamp_s, horizon.planner, start)):
                self._gate.asked(stamp_s)
            if self.course.length_m - state.s_m <= _FINISHED_M:
                return self._finished(stamp_s, state)
            good, fallback = horizon.solve(state, start, plans.plan, self.rider.w_prime_j)
            return self._advice(stamp_s, state, good, fallback=fallback)

    def _replace_planner(self) -> None:
        """Rebuild the horizon planner for the CP in use and the plan in force. Called
        with `self._solve_lock` held."""
        with self._lock:
            rider = dataclasses.replace(self.rider, critical_power_w=self._balance.cp_w)
            plan = self._plans.plan
            self._planner_stale = False
        self.horizon.rebuild(rider, plan)

    def close(self) -> None:
        """Stop the background re-solve (a solve still running is abandoned)."""
        self._plans.close()

    def _refit(self, stamp_s: float, state: RiderState) -> bool:
        """Let the CP monitor judge the last target against the power delivered
        (`cp_monitor`); after a refit the planner is rebuilt (`_replace_planner`) and the
        plan, solved for another CP, is no longer followed (`PlanInForce.follows`) until
        the rest is re-solved with it. With `self._lock` held. Returns whether CP moved."""
        assert self._last_target_w is not None
        refit = self._cp.observe(stamp_s, state, self._last_target_w)
        if refit is None:
            return False
        self._stats["cp_refits"] += 1
        self._stats[f"cp_refits_{refit.direction}"] += 1
        return True

    def _advice(self, stamp_s: float, state: RiderState, good: Solution, *,
                fallback: bool) -> Advice:
        """Advice from a solution cut at the rider's `s` (`horizon_cut`), its target and
        cue shaped into what a rider can follow (`advice_shaping`: node 0 holds the
        measured power, the OCP's initial state; the target is what the solution rides
        from there on)."""
        fields = advice_fields(self.course, state, good)
        with self._lock:
            shaped = self._shaper.shape(stamp_s, state.s_m, state.speed_mps,
                                        self._balance.cp_w, fields["horizon_s_m"],
                                        fields["horizon_power_w"], fields["horizon_speed_mps"])
            self._last_target_w = shaped["target_power_w"]
            self._stats["advice"] += 1
            cp, version = self._balance.cp_w, self._plans.version
        h = self.horizon
        return Advice(stamp_s=stamp_s, state=state, **shaped, **fields,
                      solver_status=h.status, iterations=h.iterations,
                      solve_time_s=h.solve_time_s, fallback=fallback, cp_in_use_w=cp,
                      plan_version=version)

    def _finished(self, stamp_s: float, state: RiderState) -> Advice:
        """Past the finish line: nothing to plan; the advice says so (coast, 0 W)."""
        self.horizon.report("finished")
        with self._lock:
            self._last_target_w = 0.0
            self._shaper.reset()
            self._stats["advice"] += 1
            cp, version = self._balance.cp_w, self._plans.version
        return Advice(stamp_s=stamp_s, state=state, target_power_w=0.0, cue=Cue.COAST,
                      **finished_fields(self.course, state), solver_status="finished",
                      iterations=0, solve_time_s=0.0, cp_in_use_w=cp, plan_version=version)

    # ---- diagnostics and persistence ------------------------------------------------------------
    def diagnostics(self, stamp_s: float) -> list[Diagnostic]:
        """Solver health, the CP belief, input freshness per sensor, rejected inputs."""
        st, h = self.settings, self.horizon
        with self._lock:
            rejects = {k: v for k, v in self._estimator.counters.items()
                       if not k.endswith("_accepted")}
            last_input = dict(self._last_input)
            stats = dict(self._stats)
            rider_model = self._cp.diagnostic(stamp_s)
            sensors = [name for name, _ in self._estimator.hooks.values()]
        solver = solver_diagnostic(
            stamp_s, h.status, h.status == ON_PLAN, h.iterations, h.consecutive_failures,
            st.failures_for_error, stats, self._plans.version,
            self._plans.plan.solver_status, None if st.deterministic else h.solve_time_s)
        inputs = input_diagnostics(stamp_s, sensors, last_input, st.stale_after_s, rejects,
                                   self._reported_rejects)
        self._reported_rejects = rejects
        return [solver, rider_model, *inputs]

    def snapshot(self) -> dict[str, Any]:
        """W' balance, the CP in use, progress and the replan clock, JSON-serialisable."""
        with self._lock:
            return {"estimator": self._estimator.snapshot(),
                    "cp_in_use_w": self._balance.cp_w,
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
            self._balance.use_critical_power(float(snap.get("cp_in_use_w",
                                                            self.rider.critical_power_w)))
            self._last_advice_stamp = snap["last_advice_stamp_s"]
            self._shaper.reset()
            self._last_target_w = None
