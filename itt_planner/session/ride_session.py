"""One pacing session: the engine fed with samples, ticked on the stamp clock, its advice
sent to sinks.

Both edges drive this object, so a ROS 2 node and an embedded replay of the same log
give the same advice and the same review: the replay (`replay.py`) only reads and paces
a log, the node (`itt_planner_ros.pacing_node`) only converts ROS messages.

- `RideSession.open(config, ...)` builds the engine (`config.build_engine`) and opens the
  sinks (`sinks.Sinks`): an MCAP ride log, a Rerun recording, a `publish` callback (the
  node's publishers).
- `on_sample` feeds one sample of any registered type to the engine and the sinks.
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
import threading
from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING, Any

from itt_planner.live.advice import Advice, Diagnostic, Level
from itt_planner.live.samples import Sample
from itt_planner.model.conditions import Conditions, own_air_note
from itt_planner.session.config import SessionConfig, build_engine
from itt_planner.session.sinks import Publish, Sinks

if TYPE_CHECKING:
    from itt_planner.live.engine import PacingEngine
    from itt_planner.logs.ridelog import RawRecord
    from itt_planner.logs.ridelog_writer import RideLogWriter
    from itt_planner.ocp.plan import Plan
    from itt_planner.view.rerun_log import RideRecorder

log = logging.getLogger(__name__)


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
        self.sinks = Sinks(writer, recorder, publish, engine.plan_version)
        #: Every advice, for `advice_stats` (a replay keeps them; a live node does not).
        self.advice: list[Advice] | None = [] if keep_advice else None
        self.advice_out = 0
        self.fallbacks = 0
        #: Input messages that did not decode, per topic (counted, never fatal).
        self.malformed: Counter[str] = Counter()
        self._last_diagnostics: float | None = None
        self._closed = False
        # A tick and close() exclude each other: a timer firing while the node stops must
        # not count an advice the closed log no longer takes.
        self._tick_lock = threading.RLock()

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
            from itt_planner.logs.ridelog import SESSION_METADATA  # noqa: PLC0415
            from itt_planner.logs.ridelog_writer import RideLogWriter, RideMetadata  # noqa: PLC0415

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
        if recorder is not None:
            recorder.log_notes(session.setup_warnings())
        return session

    @property
    def plan(self) -> Plan:
        """The full-course plan in force (the engine's)."""
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
        self.engine.on_sample(sample)
        self.sinks.sample(sample, lambda: self.engine.estimate, raw)

    def on_malformed(self, topic: str, reason: str) -> None:
        """Count an input message that did not decode (reported in the diagnostics)."""
        self.malformed[topic] += 1
        log.warning("malformed message on %s dropped (%s); %d so far", topic, reason,
                    self.malformed[topic])

    def write_raw(self, raw: RawRecord) -> None:
        """Copy a log message that is no input sample (e.g. /clock) to the output log."""
        self.sinks.raw(raw)

    # ---- the timer ------------------------------------------------------------------
    def advance_to(self, stamp_s: float) -> None:
        """Run every tick of the stamp-clock grid before `stamp_s`.

        The session's timer fires every `min(replan_period_s, diagnostics_period_s)` of
        stamp time on a grid of whole multiples of that period, from the first stamp it
        sees (a replay's first message, a node's first clock reading), so a node and a
        replay of one log advise at the same stamps. The tick at T runs once the clock
        has moved past T: every input stamped up to T is in before the engine plans. A
        gap in the stamps is ticked through, unless it is longer than `max_catch_up_s` (a
        restarted player jumping ahead): then the grid moves on to `stamp_s`.
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
        with self._tick_lock:
            return None if self._closed else self._tick_open(stamp_s)

    def _tick_open(self, stamp_s: float) -> Advice | None:
        advice = self.engine.update(stamp_s)
        if advice is not None:
            self.advice_out += 1
            self.fallbacks += bool(advice.fallback)
            if self.advice is not None:
                self.advice.append(advice)
            self.sinks.advice(advice, self.engine.plan, stamp_s)
        else:
            self.sinks.state(lambda: self.engine.state)
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
        self.sinks.diagnostics(diagnostics, stamp_s)

    # ---- reporting ------------------------------------------------------------------
    @property
    def conditions(self) -> Conditions:
        """The grip, wind and air the session's plans are solved in."""
        return self.engine.horizon.planner.conditions

    def setup_warnings(self, recorded_air_temperature_c: float = math.nan) -> list[str]:
        """What the session's set-up assumes that the course says otherwise (known at
        start: the node logs them then): the course's own air, at the temperature a
        replayed ride's records give (`recorded_air_temperature_c`), else the ride's the
        course was built from, else ISA's 15 C, unless the config gave the day's."""
        if math.isfinite(self.config.air_temperature_c):
            return []
        course = self.engine.course
        if not math.isfinite(recorded_air_temperature_c):
            recorded_air_temperature_c = course.recorded_air_temperature_c
        note = own_air_note(course.mean_altitude_m, self.conditions.air_density_kgpm3,
                            recorded_air_temperature_c)
        return [note] if note else []

    def warnings(self, recorded_air_temperature_c: float = math.nan) -> list[str]:
        """What the session did not use silently, one line each with its count."""
        counts = self.engine.counts
        out = self.setup_warnings(recorded_air_temperature_c)
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
        models = self.engine.counters
        if models.get("course_replans_model_1d-line", 0):  # `live.resolve_model`
            out.append(f"{models['course_replans_model_1d-line']} re-solves of the rest of the "
                       "course were 1D on the line of the plan in force, "
                       f"{models.get('course_replans_model_3d', 0)} 3D "
                       f"({models.get('course_replans_line_refused', 0)} where the 1D was "
                       "refused: a corner ahead needs the 3D; "
                       f"{models.get('course_replans_line_after_3d_failed', 0)} on the line "
                       "after the 3D failed)")
        held = counts.course_replans_backed_off + counts.course_replans_skipped_stopped
        if held:  # `live.resolve_gate`
            out.append(f"{held} re-solves of the rest of the course were held "
                       f"({counts.course_replans_asked} asked): "
                       f"{counts.course_replans_backed_off} backed off (the rider left the new "
                       f"plans soon after adoption), {counts.course_replans_skipped_stopped} "
                       "while the rider was stopped")
        if models.get("cp_up_held", 0):  # `live.cp_monitor`: holding
            out.append(f"{models['cp_up_held']} time(s) the W' balance went below zero "
                       "while the power held proved no higher CP: W' shown as 0, CP kept")
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
        tmp.replace(path)

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
        with self._tick_lock:  # waits for a tick in progress
            if self._closed:
                return
            self._closed = True
        try:
            self.engine.close()
        finally:
            self.sinks.close()
