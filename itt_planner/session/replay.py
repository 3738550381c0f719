"""The embedded replay: a ride log fed straight into a pacing session, in one process.

This module only reads and paces the log; the session (`session.RideSession`, the same
one the ROS 2 node drives) owns the engine and the outputs. Messages go to the session
in log (= stamp) order and its timer runs on the stamps only, so a replay is
deterministic and runs as fast as the planner allows (or paced at a multiple of real
time). The output log holds every input message, copied byte for byte, plus every
advice, target power, target line and diagnostics message; a Rerun recording can be
written alongside. A damaged input is replayed as far as it can be read, the output is
finished, and the damage is reported in the result.
"""

from __future__ import annotations

import math
import sys
import time
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from tqdm import tqdm

from itt_msgs_py import registry, topics
from itt_planner.errors import RideLogError
from itt_planner.live.advice_shaping import advice_stats
from itt_planner.logs.ridelog import (
    METADATA_NAME,
    SESSION_METADATA,
    RideLogReader,
    message_count,
)
from itt_planner.logs.ridelog_writer import RideMetadata
from itt_planner.session.config import SessionConfig
from itt_planner.session.ride_session import RideSession


@dataclass(frozen=True)
class ReplaySettings:
    """How to pace a replay (what decides the advice is the `SessionConfig`).

    Attributes:
        speed: pace as `speed` x real time by the stamps (1.0 = real time); None = as
            fast as possible.
        remap: (topic of the log, pacing topic it is read as) pairs, as `ros2 bag play
            --remap`: a log recorded from other drivers' topics (`parse_remap`).
    """

    speed: float | None = None
    remap: tuple[tuple[str, str], ...] = ()

    def __post_init__(self) -> None:
        if self.speed is not None and not (self.speed > 0 and math.isfinite(self.speed)):
            raise ValueError(f"replay speed must be > 0 (or None for max), got {self.speed}")


@dataclass
class ReplayResult:
    """Counts and timing of one replay (the CLI's `--json` object)."""

    messages_in: int = 0
    samples_in: int = 0
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
    counts: dict[str, Any] = field(default_factory=dict)
    advice_stats: dict[str, Any] = field(default_factory=dict)
    #: The grip, wind and air the plans were solved in (`Conditions`, SI units).
    conditions: dict[str, float] = field(default_factory=dict)

    @property
    def realtime_factor(self) -> float:
        """Ride time replayed per second of wall time."""
        return self.ride_duration_s / self.wall_time_s if self.wall_time_s > 0 else math.inf

    def as_dict(self) -> dict[str, Any]:
        """Plain JSON-able values."""
        solve = sorted(self.solve_times_s)
        return {
            "messages_in": self.messages_in, "samples_in": self.samples_in,
            "advice_out": self.advice_out,
            "ride_duration_s": self.ride_duration_s, "wall_time_s": self.wall_time_s,
            "realtime_factor": self.realtime_factor,
            "output": str(self.output) if self.output else None,
            "rrd": str(self.rrd) if self.rrd else None,
            "warnings": list(self.warnings), "errors": list(self.errors),
            "topics_out": dict(self.topics_out), "fallbacks": self.fallbacks,
            "counts": dict(self.counts), "advice_stats": dict(self.advice_stats),
            "conditions": dict(self.conditions),
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


def replay(log_path: str | Path, session: RideSession, *,
           settings: ReplaySettings = ReplaySettings(), progress: bool = False) -> ReplayResult:
    """Feed a ride log into `session` on its stamp clock; the session writes the outputs.

    The session is closed at the end (its output log finished, Rerun flushed), also when
    reading fails.

    Args:
        log_path: the input MCAP ride log.
        session: the pacing session (built by the caller, so tests and benchmarks can
            vary its engine).
        settings: pacing options.
        progress: show a progress bar on stderr.

    Returns:
        The counts; damage of the input is in `errors`, never raised.

    Raises:
        RideLogError: the input cannot be opened at all, the output cannot be written, or
            a remap names a topic the engine does not read.
    """
    namespace = session.config.namespace
    writer = session.sinks.writer
    result = ReplayResult(output=writer.path if writer else None)
    replaced: Counter[str] = Counter()
    try:
        reader = RideLogReader(log_path, namespace=namespace, remap=dict(settings.remap))
        inputs = [t.name(namespace) for t in registry.INPUT_TOPICS]
        if unknown := [dst for _, dst in settings.remap if dst not in inputs]:
            raise RideLogError(f"--remap to {', '.join(unknown)}: not a topic the engine "
                               f"reads ({', '.join(inputs)})")
    except BaseException:
        session.close()
        raise
    bar = tqdm(total=message_count(log_path), unit="msg", file=sys.stderr,
               disable=not progress, desc=Path(log_path).name)
    start = time.perf_counter()
    try:
        try:
            _feed(reader, session, _Pacer(settings.speed), bar, result, replaced)
        except RideLogError as err:
            # Everything readable was replayed; finish the output and report the damage.
            result.errors.append(str(err))
        if not result.samples_in:
            result.errors.append(_no_inputs(log_path, reader, namespace))
        session.finish()
        if writer is not None:
            for name, record in reader.metadata.items():
                if name != SESSION_METADATA:  # an earlier replay's: the session writes its own
                    writer.add_metadata(name, record)
    finally:
        bar.close()
        session.close()
    result.wall_time_s = time.perf_counter() - start
    _report(result, session, reader, replaced)
    return result


def _feed(reader: RideLogReader, session: RideSession, pacer: _Pacer, bar: tqdm[Any],
          result: ReplayResult, replaced: Counter[str]) -> None:
    """Every message of the log into the session, in log order (samples to the engine,
    the rest copied); the output topics of an earlier replay are dropped (`replaced`).

    Raises:
        RideLogError: after the last readable message, when the log is damaged.
    """
    own_topics = {t.name(session.config.namespace) for t in topics.OUTPUT_TOPICS}
    first: float | None = None
    for raw, value in reader.decoded():
        bar.update()
        if raw.topic in own_topics:  # an earlier replay's output: recomputed here
            replaced[raw.topic] += 1
            continue
        stamp = raw.log_time_ns / 1e9  # correctly rounded: whole seconds stay whole
        session.advance_to(stamp)  # the advice of earlier stamps goes out first
        pacer.wait(stamp)
        result.messages_in += 1
        first = stamp if first is None else first
        result.ride_duration_s = max(result.ride_duration_s, stamp - first)
        if registry.is_sample(value):
            result.samples_in += 1
            session.on_sample(value, raw)
        else:
            session.write_raw(raw)


def _no_inputs(log_path: str | Path, reader: RideLogReader, namespace: str) -> str:
    """What to say when a log gave the engine nothing: what it wants, what the log has."""
    wanted = ", ".join(f"{t.name(namespace)} ({t.msgtype})" for t in registry.INPUT_TOPICS)
    found = ", ".join(f"{topic} ({n})" for topic, n in sorted(reader.skipped.items()))
    return (f"{log_path}: no GPS, speed or power message: the engine reads {wanted}; "
            f"the log's other topics: {found or 'none'}; read one of them as a pacing topic "
            "with --remap LOG_TOPIC:=PACING_TOPIC, or give the log's --namespace")


def parse_remap(items: list[str] | tuple[str, ...]) -> tuple[tuple[str, str], ...]:
    """`["/fix:=/itt/gps/fix"]` -> `(("/fix", "/itt/gps/fix"),)`.

    Raises:
        ValueError: an item that is not `FROM:=TO` with two absolute topic names.
    """
    pairs = []
    for item in items:
        src, sep, dst = item.partition(":=")
        if not (sep and src.startswith("/") and dst.startswith("/")):
            raise ValueError(f"--remap {item!r}: expected LOG_TOPIC:=PACING_TOPIC, both "
                             "absolute (/fix:=/itt/gps/fix)")
        pairs.append((src, dst))
    return tuple(pairs)


def _report(result: ReplayResult, session: RideSession, reader: RideLogReader,
            replaced: Counter[str]) -> None:
    """The counts of a finished replay and its warnings, with what was not used."""
    if session.sinks.writer is not None:
        result.topics_out = dict(session.sinks.writer.counts)
    result.solve_times_s = list(session.engine.solve_times_s)
    result.advice_out = session.advice_out
    result.fallbacks = session.fallbacks
    result.counts = session.counts()
    result.conditions = asdict(session.conditions)
    if math.isfinite(session.config.air_temperature_c):
        result.conditions["air_temperature_c"] = session.config.air_temperature_c
    result.warnings.extend(reader.warnings)
    result.warnings.extend(f"input had {n} messages on {topic}: replaced by the replay's own"
                           for topic, n in sorted(replaced.items()))
    ride = RideMetadata.from_record(reader.metadata.get(METADATA_NAME, {}))
    result.warnings.extend(session.warnings(ride.air_temperature_c))
    if session.advice is not None:
        result.advice_stats = advice_stats(session.advice)
        if unexplained := result.advice_stats["unexplained_steps"]:
            result.warnings.append(f"{unexplained} target power steps over "
                                   f"{result.advice_stats['step_limit_w']:.0f} W without a cue")


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


def replay_ride(log_path: str | Path, config: SessionConfig, *,
                output: str | Path | None = None, rrd: str | Path | None = None,
                rerun_sinks: tuple[str, ...] = (),
                settings: ReplaySettings = ReplaySettings(),
                progress: bool = False) -> ReplayResult:
    """Open a session of `config` (course, rider, cached full-course plan) and replay.

    `rrd` saves a Rerun recording; `rerun_sinks` are more Rerun destinations in
    `RerunSink.parse` form (`spawn`, `connect[:URL]`, `serve`), fed live by the same
    stream.

    Raises:
        CourseError, RiderError, SolveError: the course, rider or plan is unusable.
        RideLogError: the input log cannot be opened, or the output cannot be written.
    """
    sinks = ((f"file:{rrd}",) if rrd is not None else ()) + tuple(rerun_sinks)
    session = RideSession.open(config, output_log=output, rerun_sinks=sinks,
                               metadata={"input": str(log_path)}, keep_advice=True)
    result = replay(log_path, session, settings=settings, progress=progress)
    result.rrd = Path(rrd) if rrd is not None else None
    return result
