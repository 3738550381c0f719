"""One pacing session: course, rider, plan and engine; samples in, advice out to sinks.

Both edges drive this object, so a ROS 2 node and an embedded replay of the same log
give the same advice and the same review: the replay (`replay.py`) only reads and paces
a log, the node (`itt_planner_ros.pacing_node`) only converts ROS messages.

- `SessionConfig` is everything that decides the advice (loaded once at the edge: CLI
  options or ROS parameters).
- `RideSession.open(config, ...)` loads the course, rider and full-course plan (from the
  plan cache) and builds the engine; outputs are sinks: an MCAP ride log, a Rerun
  recording, and a `publish` callback (the node's publishers).
- `on_sample` feeds one sample (GPS, speed, power) to the engine and the sinks.
- `advance_to(stamp_s)` runs the session's timer on the stamp clock (a fixed grid, the
  same for a node and a replay); at each tick the engine decides whether a replan is
  due; diagnostics go out every `diagnostics_period_s` of stamp time.
- `warnings()` turns what was not used silently (fallbacks, failed re-solves, refits,
  an unconverged plan) into one line each, with counts.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import os
import threading
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from itt_msgs_py import DEFAULT_NAMESPACE
from itt_planner.live.advice import Advice, Diagnostic, Level
from itt_planner.errors import SolveError
from itt_planner.live.samples import GpsFix, PowerReading, Sample, WheelSpeed

if TYPE_CHECKING:
    from itt_planner.live.engine import PacingEngine
    from itt_planner.ocp.plan import Plan
    from itt_planner.view.rerun_log import RideRecorder
    from itt_planner.logs.ridelog import RawRecord, RideLogWriter

log = logging.getLogger(__name__)

#: The output log's metadata record of the session's settings and plan status (the name
#: is the one reports have read since the embedded replay wrote it).
#: IPOPT's own default for `max_wall_time`: no limit.
NO_WALL_TIME_LIMIT_S = 1e20


@dataclass(frozen=True)
class SessionConfig:
    """What decides the advice of a session (node parameters, replay options).

    Attributes:
        course: course spec for `load_course` (demo name, GPS file, `.course.npz`).
        rider: rider preset name or YAML file.
        model: full-course plan model, "3d" or "1d".
        plan: a saved full-course plan (`Plan.save`); "" to take it from `plan_cache`.
        plan_cache: directory of cached full-course plans (solved there when missing).
        horizon_m: receding-horizon length.
        replan_period_s: stamp time between two advices.
        on_plan_band_j: W' deviation from the plan within which the advice is the plan
            itself (`EngineSettings`); 0.0 replans every period.
        course_replan_period_s: off the plan, the rest of the course is re-solved at most
            this often (`CourseReplanSettings`); 0.0 never.
        line_gate_m: the horizon plans from the advised line unless GPS puts the rider
            further off it than this (`EngineSettings`).
        diagnostics_period_s: stamp time between two diagnostics messages.
        deterministic: no wall-clock values in advice and diagnostics and no wall-time
            caps, so two runs over one log give byte-identical advice (replays); False
            is the live behaviour (overruns judged by the wall clock).
        namespace: ROS namespace of the pacing topics (MCAP topic names).
    """

    course: str = "verona-like"
    rider: str = "paper"
    model: str = "3d"
    plan: str = ""
    plan_cache: str = ".itt_cache"
    horizon_m: float = 1000.0
    replan_period_s: float = 1.0
    on_plan_band_j: float = 2000.0
    course_replan_period_s: float = 30.0
    line_gate_m: float = 5.0
    diagnostics_period_s: float = 1.0
    deterministic: bool = False
    namespace: str = DEFAULT_NAMESPACE


def build_engine(config: SessionConfig) -> PacingEngine:
    """Load the course, rider and full-course plan of `config` and build the engine.

    Raises:
        CourseError, RiderError, SolveError: the course, rider or plan is unusable.
    """
    # Heavy (CasADi): imported when a session is actually built.
    from itt_planner.model.conditions import Conditions  # noqa: PLC0415
    from itt_planner.course.loader import load_course  # noqa: PLC0415
    from itt_planner.live.course_replan import CourseReplanSettings  # noqa: PLC0415
    from itt_planner.live.engine import EngineSettings, PacingEngine  # noqa: PLC0415
    from itt_planner.ocp.horizon import HorizonPlanner  # noqa: PLC0415
    from itt_planner.ocp.horizon_settings import HorizonSettings  # noqa: PLC0415
    from itt_planner.ocp.course_settings import OcpSettings  # noqa: PLC0415
    from itt_planner.ocp.plan import Plan  # noqa: PLC0415
    from itt_planner.ocp.cache import load_or_solve  # noqa: PLC0415
    from itt_planner.model.rider import load_rider  # noqa: PLC0415
    from itt_planner.ocp.solver import PlanStatus  # noqa: PLC0415

    course = load_course(config.course)
    rider = load_rider(config.rider)
    conditions = Conditions()
    if config.plan:
        plan = Plan.load(config.plan)
    else:
        plan = load_or_solve(course, rider, conditions, OcpSettings(), config.model,
                             cache_dir=Path(config.plan_cache))
    if plan.status in (PlanStatus.FAILED, PlanStatus.INVALID):
        # A capped plan is still a verified trajectory (advised, with a warning); a failed
        # or invalid one is not a plan a rider should be given.
        raise SolveError(f"the full-course plan of {config.course} for {config.rider} is "
                         f"{plan.status} ({plan.solver_status}): not used",
                         status=plan.solver_status)
    horizon = HorizonSettings(horizon_m=config.horizon_m)
    if config.deterministic:
        # IPOPT's wall-time cap would make the result depend on the machine's load; the
        # iteration cap stays the budget.
        horizon = dataclasses.replace(horizon, max_wall_time_s=NO_WALL_TIME_LIMIT_S)
    planner = HorizonPlanner(course, rider, plan, conditions=conditions, settings=horizon)
    settings = EngineSettings(
        replan_period_s=config.replan_period_s, horizon_m=config.horizon_m,
        on_plan_band_j=config.on_plan_band_j, line_gate_m=config.line_gate_m,
        deterministic=config.deterministic,
        course_replan=CourseReplanSettings(period_s=config.course_replan_period_s))
    return PacingEngine(course, rider, plan, conditions=conditions, planner=planner,
                        settings=settings)


#: What the node publishes: an advice, or a diagnostics batch with its stamp.
Publish = Callable[[Advice | None, list[Diagnostic] | None, float], None]


class RideSession:
    """A pacing session (see the module docstring).

    Args:
        config: what decides the advice.
        engine: the engine (`build_engine(config)`; tests pass their own).
        writer: the MCAP ride log of inputs and outputs, or None.
        recorder: the Rerun recorder, or None.
        publish: called with each advice and each diagnostics batch (the node's
            publishers), or None.
    """

    def __init__(self, config: SessionConfig, engine: PacingEngine, *,
                 writer: RideLogWriter | None = None, recorder: RideRecorder | None = None,
                 publish: Publish | None = None, keep_advice: bool = False,
                 max_catch_up_s: float = math.inf) -> None:
        self.config = config
        self.tick_period_s = min(config.replan_period_s, config.diagnostics_period_s)
        self.max_catch_up_s = max_catch_up_s
        self._first_tick: float | None = None
        self._ticks = 0
        self._last_stamp = -math.inf
        self.engine = engine
        self.writer = writer
        self.recorder = recorder
        self.publish = publish
        #: Every advice, for `advice_stats` (a replay keeps them; a live node does not).
        self.advice: list[Advice] | None = [] if keep_advice else None
        self._plan_version = engine.plan_version
        self.advice_out = 0
        self.fallbacks = 0
        #: Input messages that did not decode, per topic (counted, never fatal).
        self.malformed: Counter[str] = Counter()
        self._io_lock = threading.Lock()  # the MCAP writer is not thread-safe
        self._last_diagnostics: float | None = None
        self._closed = False

    @classmethod
    def open(cls, config: SessionConfig, *, output_log: str | Path | None = None,
             rerun_sinks: tuple[str, ...] = (), publish: Publish | None = None,
             metadata: dict[str, str] | None = None, keep_advice: bool = False,
             max_catch_up_s: float = math.inf) -> RideSession:
        """Build the engine and open the sinks: MCAP `output_log`, Rerun `rerun_sinks`
        (`RerunSink.parse` forms: `file:X.rrd`, `spawn`, `connect[:URL]`, `serve`).

        Raises:
            CourseError, RiderError, SolveError: the course, rider or plan is unusable.
            RideLogError: the output log cannot be created.
        """
        writer = recorder = engine = None
        if output_log:  # before the (slow) plan: a bad path fails at once
            from itt_planner.logs.ridelog import SESSION_METADATA, RideLogWriter, RideMetadata  # noqa: PLC0415

            writer = RideLogWriter(output_log, namespace=config.namespace,
                                   metadata=RideMetadata(source="itt-planner session",
                                                         rider=config.rider))
        try:
            engine = build_engine(config)
            if rerun_sinks:
                from itt_planner.view.rerun_log import RideRecorder  # noqa: PLC0415
                from itt_planner.view.rerun_sink import RerunSink, open_recording  # noqa: PLC0415

                rec = open_recording([RerunSink.parse(s) for s in rerun_sinks])
                recorder = RideRecorder(rec, engine.course, engine.rider, engine.plan)
                recorder.log_course()
        except BaseException:
            if engine is not None:
                engine.close()
            if writer is not None:
                writer.close()
            raise
        session = cls(config, engine, writer=writer, recorder=recorder, publish=publish,
                      keep_advice=keep_advice, max_catch_up_s=max_catch_up_s)
        if writer is not None:
            writer.add_metadata(SESSION_METADATA, {**session.describe(), **(metadata or {})})
        return session

    @property
    def plan(self) -> Plan:
        """The full-course plan the session started from."""
        return self.engine.plan

    def describe(self) -> dict[str, str]:
        """The settings and the plan's status, as strings (MCAP metadata)."""
        fields = {k: str(v) for k, v in dataclasses.asdict(self.config).items()}
        return {**fields, "plan_status": self.plan.solver_status}

    # ---- inputs ---------------------------------------------------------------------
    def on_sample(self, sample: Sample, raw: RawRecord | None = None) -> None:
        """Feed one input sample to the engine and the sinks; never raises on odd values.

        `raw` is the sample's message as read from a log (copied byte for byte into the
        output log); without it the sample is encoded anew.
        """
        engine, recorder = self.engine, self.recorder
        if isinstance(sample, GpsFix):
            engine.on_gps(sample)
            if recorder is not None:
                recorder.log_gps(sample, engine.state)
        elif isinstance(sample, WheelSpeed):
            engine.on_speed(sample)
            if recorder is not None:
                recorder.log_speed(sample)
        elif isinstance(sample, PowerReading):
            engine.on_power(sample)
            if recorder is not None:
                recorder.log_power(sample)
        if self.writer is not None:
            with self._io_lock:
                if raw is not None:
                    self.writer.write_raw(raw)
                else:
                    self.writer.write_sample(sample)

    def on_malformed(self, topic: str, reason: str) -> None:
        """Count an input message that did not decode (reported in the diagnostics)."""
        self.malformed[topic] += 1
        log.warning("malformed message on %s dropped (%s); %d so far", topic, reason,
                    self.malformed[topic])

    def write_raw(self, raw: RawRecord) -> None:
        """Copy a log message that is no input sample (e.g. /clock) to the output log."""
        if self.writer is not None:
            with self._io_lock:
                self.writer.write_raw(raw)

    # ---- the timer ------------------------------------------------------------------
    def advance_to(self, stamp_s: float) -> None:
        """Run every tick of the stamp-clock grid before `stamp_s`.

        The session's timer fires every `min(replan_period_s, diagnostics_period_s)` of
        stamp time on a grid of whole multiples of that period, from the first stamp it
        sees (a replay's first message, a node's first clock reading), so a node and a
        replay of one log advise at the same stamps. The tick at T runs once the clock has moved past T: every input stamped
        up to T is in before the engine plans. A gap in the stamps is ticked through,
        unless it is longer than `max_catch_up_s` (a restarted player jumping ahead):
        then the grid moves on to `stamp_s`.
        """
        if self._first_tick is None:
            # On whole multiples of the period: a node that starts late (its first clock
            # reading after the log's first stamp) still ticks at the replay's stamps.
            self._first_tick = math.floor(stamp_s / self.tick_period_s) * self.tick_period_s
        if stamp_s - self._next_tick() > self.max_catch_up_s:
            self._ticks = math.floor((stamp_s - self._first_tick) / self.tick_period_s)
        while self._next_tick() < stamp_s:
            self._tick(self._next_tick())
            self._ticks += 1
        self._last_stamp = max(self._last_stamp, stamp_s)

    def finish(self) -> None:
        """Run the ticks up to and including the last stamp seen (end of a log)."""
        if self._first_tick is None:
            return
        while self._next_tick() <= self._last_stamp:
            self._tick(self._next_tick())
            self._ticks += 1

    def _next_tick(self) -> float:
        assert self._first_tick is not None
        # Multiplied, not accumulated: no drift over a long ride.
        return self._first_tick + self._ticks * self.tick_period_s

    def _tick(self, stamp_s: float) -> Advice | None:
        """Run the engine's replan at `stamp_s`; send advice and due diagnostics out."""
        advice = self.engine.update(stamp_s)
        if advice is not None:
            self.advice_out += 1
            self.fallbacks += bool(advice.fallback)
            if self.advice is not None:
                self.advice.append(advice)
            if self.writer is not None:
                with self._io_lock:
                    self.writer.write_advice(advice)
            if self.recorder is not None:
                if advice.plan_version != self._plan_version:  # a re-solved plan adopted
                    self._plan_version = advice.plan_version
                    self.recorder.log_plan(self.engine.plan, advice.plan_version)
                self.recorder.log_state(advice.state)
                self.recorder.log_advice(advice)
            if self.publish is not None:
                self.publish(advice, None, stamp_s)
        elif self.recorder is not None and (state := self.engine.state) is not None:
            self.recorder.log_state(state)
        last = self._last_diagnostics
        period = self.config.diagnostics_period_s
        # A clock that jumps back (a restarted player) restarts the diagnostics period.
        if last is None or stamp_s - last >= period - 1e-6 or stamp_s < last:
            self._last_diagnostics = stamp_s
            self.emit_diagnostics(stamp_s, [*self.engine.diagnostics(stamp_s),
                                            self.diagnostic(stamp_s)])
        return advice

    def diagnostic(self, stamp_s: float) -> Diagnostic:
        """The session's own health: malformed inputs dropped, advice sent."""
        bad = sum(self.malformed.values())
        return Diagnostic(
            stamp_s, "itt_planner/session", Level.WARN if bad else Level.OK,
            f"{bad} malformed input message(s) dropped" if bad else "ok",
            {"advice_out": str(self.advice_out), "fallbacks": str(self.fallbacks),
             **{f"malformed/{k}": str(v) for k, v in sorted(self.malformed.items())}})

    def emit_diagnostics(self, stamp_s: float, diagnostics: list[Diagnostic]) -> None:
        """Send a diagnostics batch to every sink."""
        if self.writer is not None:
            with self._io_lock:
                self.writer.write_diagnostics(diagnostics, stamp_s)
        if self.recorder is not None:
            self.recorder.log_diagnostics(diagnostics)
        if self.publish is not None:
            self.publish(None, diagnostics, stamp_s)

    # ---- reporting ------------------------------------------------------------------
    def warnings(self) -> list[str]:
        """What the session did not use silently, one line each with its count."""
        counts = self.engine.counts
        out = []
        if not counts.plan_converged:
            out.append(f"the plan in force is not converged ({self.engine.plan.status}, "
                       f"{counts.plan_status}): advice from it is not optimal")
        if self.fallbacks:
            share = 100.0 * self.fallbacks / max(self.advice_out, 1)
            out.append(f"{self.fallbacks} of {self.advice_out} advice ({share:.1f} %) were "
                       "fallbacks: the last good advice after a failed or overrun solve")
        if counts.unconverged_solves:
            out.append(f"{counts.unconverged_solves} of {counts.solves} horizon solves did "
                       "not converge (a feasible iterate at the budget was advised)")
        if counts.course_replan_failures:
            out.append(f"{counts.course_replan_failures} of {counts.course_replans_asked} "
                       "re-solves of the rest of the course failed: the plan in force stayed")
        refits = counts.refits_up + counts.refits_down
        if refits:
            out.append(f"critical power refitted {refits} time(s) ({counts.refits_down} down, "
                       f"{counts.refits_up} up) to {counts.cp_in_use_w:.0f} W (see the "
                       "itt_planner/rider_model diagnostics)")
        return out

    def counts(self) -> dict[str, Any]:
        """The engine's events and input counters plus the session's advice counts."""
        return {**self.engine.counters, **dataclasses.asdict(self.engine.counts),
                "advice_out": self.advice_out, "fallbacks": self.fallbacks}

    # ---- persistence (a restarted node resumes with the W' it had) --------------------
    def save_state(self, path: Path) -> None:
        """Write the engine's snapshot atomically (a kill mid-write leaves the old file).

        Raises:
            OSError: the file cannot be written.
        """
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps({"course": self.config.course,
                                   "engine": self.engine.snapshot()}), encoding="utf-8")
        os.replace(tmp, path)

    def restore_state(self, path: Path) -> float | None:
        """Resume from a snapshot `save_state` wrote for this course.

        Returns:
            The W' balance resumed with (J), or None when there is no file.

        Raises:
            ValueError: the file is unreadable or not a snapshot of this course.
        """
        if not path.is_file():
            return None
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
            if doc.get("course") != self.config.course:
                raise ValueError(f"a saved state of course {doc.get('course')!r}")
            self.engine.restore(doc["engine"])
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
            raise ValueError(f"{path}: cannot resume from it ({err})") from None
        w_prime = doc["engine"].get("estimator", {}).get("w_prime_j", math.nan)
        return float(w_prime)

    def close(self) -> None:
        """Stop the engine's worker, finish the output log and flush Rerun (idempotent)."""
        if self._closed:
            return
        self._closed = True
        try:
            self.engine.close()
        finally:
            if self.writer is not None:
                with self._io_lock:
                    self.writer.close()
            if self.recorder is not None:
                self.recorder.rec.flush(timeout_sec=10.0)
                self.recorder.rec.disconnect()
