"""The embedded replay: a ride log fed straight into the pacing engine, in one process.

Messages go to the engine in log (= stamp) order; the engine is clocked by the stamps
only, so a replay is deterministic and runs as fast as the planner allows (or paced at
a multiple of real time). The output log holds every input message, copied byte for
byte, plus every advice, target power, target line and diagnostics message; a Rerun
recording can be written alongside. A damaged input is replayed as far as it can be
read, the output is finished, and the damage is reported in the result.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from tqdm import tqdm

from itt_msgs_py import DEFAULT_NAMESPACE, topics
from itt_planner.advice import Advice, Diagnostic
from itt_planner.errors import RideLogError
from itt_planner.ridelog import RideLogReader, RideLogWriter, message_count
from itt_planner.samples import GpsFix, PowerReading, WheelSpeed
from itt_planner.state import RiderState

if TYPE_CHECKING:
    from itt_planner.rerun_log import RideRecorder

log = logging.getLogger(__name__)

REPLAY_METADATA = "itt_replay"
#: IPOPT's own default for `max_wall_time`: no limit.
NO_WALL_TIME_LIMIT_S = 1e20


class _EngineSettings(Protocol):
    replan_period_s: float


class Engine(Protocol):
    """What the replay needs of `itt_planner.engine.PacingEngine`."""

    settings: _EngineSettings

    def on_gps(self, fix: GpsFix) -> None: ...
    def on_speed(self, sample: WheelSpeed) -> None: ...
    def on_power(self, sample: PowerReading) -> None: ...
    def update(self, stamp_s: float) -> Advice | None: ...
    def diagnostics(self, stamp_s: float) -> list[Diagnostic]: ...
    @property
    def state(self) -> RiderState | None: ...
    #: Measured wall-clock solve times (s), never published.
    solve_times_s: list[float]


@dataclass(frozen=True)
class ReplaySettings:
    """How to replay.

    Attributes:
        speed: pace as `speed` x real time by the stamps (1.0 = real time); None = as
            fast as possible.
        diagnostics_period_s: stamp time between `/diagnostics` messages (the replay's
            timer ticks at this period or the engine's replan period, the shorter).
        deterministic: build the engine in its deterministic mode (no wall-clock values
            in advice and diagnostics, overruns not judged by the wall clock), so two
            replays give byte-identical output; False behaves as live, timing included.
    """

    speed: float | None = None
    diagnostics_period_s: float = 1.0
    deterministic: bool = True
    namespace: str = DEFAULT_NAMESPACE

    def __post_init__(self) -> None:
        if self.speed is not None and not (self.speed > 0 and math.isfinite(self.speed)):
            raise ValueError(f"replay speed must be > 0 (or None for max), got {self.speed}")


@dataclass
class ReplayResult:
    """Counts and timing of one replay (the CLI's `--json` object)."""

    messages_in: int = 0
    advice_out: int = 0
    ride_duration_s: float = 0.0
    wall_time_s: float = 0.0
    output: Path | None = None
    rrd: Path | None = None
    warnings: list[str] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)
    topics_out: dict[str, int] = field(default_factory=dict)
    solve_times_s: list[float] = field(default_factory=list)
    fallbacks: int = 0

    @property
    def realtime_factor(self) -> float:
        """Ride time replayed per second of wall time."""
        return self.ride_duration_s / self.wall_time_s if self.wall_time_s > 0 else math.inf

    def as_dict(self) -> dict[str, Any]:
        """Plain JSON-able values."""
        solve = sorted(self.solve_times_s)
        return {
            "messages_in": self.messages_in, "advice_out": self.advice_out,
            "ride_duration_s": self.ride_duration_s, "wall_time_s": self.wall_time_s,
            "realtime_factor": self.realtime_factor,
            "output": str(self.output) if self.output else None,
            "rrd": str(self.rrd) if self.rrd else None,
            "warnings": list(self.warnings), "errors": list(self.errors),
            "topics_out": dict(self.topics_out), "fallbacks": self.fallbacks,
            "solve_time_median_s": solve[len(solve) // 2] if solve else None,
            "solve_time_max_s": solve[-1] if solve else None,
        }


class _Pacer:
    """Sleeps so that stamps advance at `speed` x the wall clock (no-op for max speed)."""

    def __init__(self, speed: float | None) -> None:
        self.speed = speed
        self.origin: tuple[float, float] | None = None  # (first stamp, wall time then)

    def wait(self, stamp_s: float) -> None:
        if self.speed is None:
            return
        now = time.perf_counter()
        if self.origin is None:
            self.origin = (stamp_s, now)
            return
        due = self.origin[1] + (stamp_s - self.origin[0]) / self.speed
        if due > now:
            time.sleep(due - now)


def replay(log_path: str | Path, engine: Engine, *, output: str | Path | None = None,
           recorder: RideRecorder | None = None, settings: ReplaySettings = ReplaySettings(),
           metadata: dict[str, str] | None = None, progress: bool = False) -> ReplayResult:
    """Feed a ride log into `engine` and write what it advises.

    Args:
        log_path: the input MCAP ride log.
        engine: a `PacingEngine` (built by the caller, so tests and benchmarks can vary it).
        output: the output MCAP log (inputs + advice + target power + line + diagnostics).
        recorder: a Rerun `RideRecorder`, or None.
        settings: pacing and output options.
        metadata: written as the output's `itt_replay` metadata record (course, rider ...).
        progress: show a progress bar on stderr.

    Returns:
        The counts; damage of the input is in `errors`, never raised.

    Raises:
        RideLogError: the input cannot be opened at all, or the output cannot be written.
    """
    reader = RideLogReader(log_path, namespace=settings.namespace)
    result = ReplayResult(output=Path(output) if output else None)
    own_topics = {t.name(settings.namespace) for t in topics.TOPICS
                  if t.direction is topics.Direction.OUT}
    replaced: dict[str, int] = {}
    writer = RideLogWriter(output, namespace=settings.namespace) if output else None
    pacer = _Pacer(settings.speed)
    bar = tqdm(total=message_count(log_path), unit="msg", file=sys.stderr,
               disable=not progress, desc=Path(log_path).name)
    loop = _Loop(engine, writer, recorder, settings, result)
    start = time.perf_counter()
    first: float | None = None
    last: float | None = None
    try:
        try:
            for raw, value in reader.decoded():
                bar.update()
                if raw.topic in own_topics:  # an earlier replay's output: recomputed here
                    replaced[raw.topic] = replaced.get(raw.topic, 0) + 1
                    continue
                stamp = raw.log_time_ns / 1e9  # correctly rounded: whole seconds stay whole
                loop.advance_to(stamp)  # the advice of earlier stamps goes out first
                pacer.wait(stamp)
                if writer is not None:
                    writer.write_raw(raw)
                result.messages_in += 1
                first = stamp if first is None else first
                last = stamp if last is None else max(last, stamp)
                loop.feed(value)
        except RideLogError as err:
            # Everything readable was replayed; finish the output and report the damage.
            result.errors.append(str(err))
        loop.finish()
        if writer is not None and reader.metadata:
            for name, record in reader.metadata.items():
                writer.add_metadata(name, record)
        if writer is not None and metadata:
            writer.add_metadata(REPLAY_METADATA, metadata)
    finally:
        bar.close()
        if writer is not None:
            writer.close()
            result.topics_out = dict(writer.counts)
    result.wall_time_s = time.perf_counter() - start
    result.solve_times_s = list(engine.solve_times_s)
    result.ride_duration_s = (last - first) if first is not None and last is not None else 0.0
    result.warnings.extend(reader.warnings)
    result.warnings.extend(f"input had {n} messages on {topic}: replaced by the replay's own"
                           for topic, n in sorted(replaced.items()))
    return result


class _Loop:
    """Feeds values to the engine and runs its timer on the stamp clock.

    Like the node's timer under `use_sim_time`, the timer fires every `period_s` of stamp
    time from the first message (through gaps in the log too); the tick at T runs once
    the log has moved past T, so every message stamped up to T is in before the engine
    plans. The engine decides at each tick whether a replan is due.
    """

    def __init__(self, engine: Engine, writer: RideLogWriter | None,
                 recorder: RideRecorder | None, settings: ReplaySettings,
                 result: ReplayResult) -> None:
        self.engine = engine
        self.writer = writer
        self.recorder = recorder
        self.settings = settings
        self.result = result
        self.period_s = min(engine.settings.replan_period_s, settings.diagnostics_period_s)
        self.first_tick: float | None = None
        self.ticks = 0
        self.last_stamp = -math.inf
        self.last_diagnostics = -math.inf

    def _next_tick(self) -> float:
        assert self.first_tick is not None
        # Multiplied, not accumulated: no drift over a long ride.
        return self.first_tick + self.ticks * self.period_s

    def advance_to(self, stamp_s: float) -> None:
        if self.first_tick is None:
            self.first_tick = stamp_s
        while self._next_tick() < stamp_s:
            self.tick(self._next_tick())
            self.ticks += 1
        self.last_stamp = max(self.last_stamp, stamp_s)

    def finish(self) -> None:
        if self.first_tick is None:
            return
        while self._next_tick() <= self.last_stamp:
            self.tick(self._next_tick())
            self.ticks += 1

    def feed(self, value: object) -> None:
        engine, recorder = self.engine, self.recorder
        if isinstance(value, GpsFix):
            engine.on_gps(value)
            if recorder is not None:
                recorder.log_gps(value, engine.state)
        elif isinstance(value, WheelSpeed):
            engine.on_speed(value)
            if recorder is not None:
                recorder.log_speed(value)
        elif isinstance(value, PowerReading):
            engine.on_power(value)
            if recorder is not None:
                recorder.log_power(value)

    def tick(self, stamp_s: float) -> None:
        advice = self.engine.update(stamp_s)
        if advice is not None:
            self.result.advice_out += 1
            self.result.fallbacks += bool(advice.fallback)
            if self.writer is not None:
                self.writer.write_advice(advice)
            if self.recorder is not None:
                self.recorder.log_state(advice.state)
                self.recorder.log_advice(advice)
        elif self.recorder is not None and (state := self.engine.state) is not None:
            self.recorder.log_state(state)
        if stamp_s - self.last_diagnostics >= self.settings.diagnostics_period_s - 1e-6:
            self.last_diagnostics = stamp_s
            diagnostics = self.engine.diagnostics(stamp_s)
            if self.writer is not None:
                self.writer.write_diagnostics(diagnostics, stamp_s)
            if self.recorder is not None:
                self.recorder.log_diagnostics(diagnostics)


def parse_speed(text: str) -> float | None:
    """`max` -> None (as fast as possible), else the real-time multiple (`1`, `10`).

    Raises:
        ValueError: not `max` and not a positive number.
    """
    if text.strip().lower() == "max":
        return None
    value = float(text)
    if not (value > 0 and math.isfinite(value)):
        raise ValueError(f"--speed must be 'max' or a positive number, got {text!r}")
    return value


def replay_ride(log_path: str | Path, course_spec: str, rider_spec: str, *,
                output: str | Path | None = None, rrd: str | Path | None = None,
                rerun_sinks: tuple[str, ...] = (),
                settings: ReplaySettings = ReplaySettings(), replan_period_s: float = 1.0,
                horizon_m: float = 1000.0, model: str = "3d",
                cache_dir: Path = Path(".itt_cache"), progress: bool = False) -> ReplayResult:
    """Load the course, rider and full-course plan, build the engine, and replay.

    The full-course plan comes from the plan cache (solved on the first run for this
    course, rider and settings). `rrd` saves a Rerun recording; `rerun_sinks` are more
    Rerun destinations in `RerunSink.parse` form (`spawn`, `connect[:URL]`, `serve`), fed
    live by the same stream.

    Raises:
        CourseError, RiderError, SolveError: the course, rider or plan is unusable.
        RideLogError: the input log cannot be opened, or the output cannot be written.
    """
    # Heavy (CasADi, Rerun): imported when a replay actually runs.
    from itt_planner.conditions import Conditions  # noqa: PLC0415
    from itt_planner.course_loader import load_course  # noqa: PLC0415
    from itt_planner.engine import EngineSettings, PacingEngine  # noqa: PLC0415
    from itt_planner.horizon import HorizonPlanner, HorizonSettings  # noqa: PLC0415
    from itt_planner.ocp import OcpSettings  # noqa: PLC0415
    from itt_planner.plan_cache import load_or_solve  # noqa: PLC0415
    from itt_planner.rider import load_rider  # noqa: PLC0415

    course = load_course(course_spec)
    rider = load_rider(rider_spec)
    conditions = Conditions()
    plan = load_or_solve(course, rider, conditions, OcpSettings(), model, cache_dir=cache_dir)
    horizon = HorizonSettings(horizon_m=horizon_m)
    if settings.deterministic:
        # IPOPT's wall-time cap would make the result depend on the machine's load; the
        # iteration cap stays the budget.
        horizon = dataclasses.replace(horizon, max_wall_time_s=NO_WALL_TIME_LIMIT_S)
    planner = HorizonPlanner(course, rider, plan, conditions=conditions, settings=horizon)
    engine = PacingEngine(course, rider, plan, conditions=conditions, planner=planner,
                          settings=EngineSettings(replan_period_s=replan_period_s,
                                                  horizon_m=horizon_m,
                                                  deterministic=settings.deterministic))
    recorder = None
    rec = None
    sinks = ([f"file:{rrd}"] if rrd is not None else []) + list(rerun_sinks)
    if sinks:
        from itt_planner.rerun_log import RideRecorder  # noqa: PLC0415
        from itt_planner.rerun_sink import RerunSink, open_recording  # noqa: PLC0415

        rec = open_recording([RerunSink.parse(s) for s in sinks])
        recorder = RideRecorder(rec, course, rider, plan)
        recorder.log_course()
    metadata = {"input": str(log_path), "course": course_spec, "rider": rider_spec,
                "model": model, "replan_period_s": str(replan_period_s),
                "horizon_m": str(horizon_m), "plan_status": plan.solver_status}
    try:
        result = replay(log_path, engine, output=output, recorder=recorder, settings=settings,
                        metadata=metadata, progress=progress)
    finally:
        engine.close()
        if rec is not None:
            rec.flush()
            rec.disconnect()
    result.rrd = Path(rrd) if rrd is not None else None
    return result
