"""Publish a ride log on DDS as `ros2 bag play` does (rate, loop, start offset, /clock).

Each message goes out with its stored CDR bytes on its topic, at its log time scaled by
`rate`; known pacing topics keep their interface QoS (sensor data best-effort), others
are published reliable, ROS 2's default. With `clock_hz` the playback time is published
on `/clock` (rosgraph_msgs/Clock) for nodes running with `use_sim_time`.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from cyclonedds.domain import DomainParticipant

from itt_msgs_py import DEFAULT_NAMESPACE, serialize, topics, typestore
from itt_planner.dds.endpoints import RawWriter
from itt_planner.errors import RideLogError
from itt_planner.ridelog import RawRecord, RideLogReader

log = logging.getLogger(__name__)

CLOCK_TOPIC = "/clock"
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"
#: rclcpp::ClockQoS: best effort, keep last 1.
CLOCK_QOS = topics.QoS(topics.Reliability.BEST_EFFORT, depth=1)


@dataclass(frozen=True)
class PlaySettings:
    """How to play a log.

    Attributes:
        rate: playback speed factor (2.0 = twice as fast).
        loop: start over at the end, until stopped.
        clock_hz: publish `/clock` at this wall-clock rate; 0 for no clock.
        start_offset_s: skip the first seconds of the log.
        topics: only these topics (fully qualified); empty for all.
        wait_for_matched_s: before playing, wait up to this long for every input topic
            of the log to have a subscriber (0: start at once, like `ros2 bag play`).
        namespace: namespace of the pacing topics in the log (for their QoS).
    """

    rate: float = 1.0
    loop: bool = False
    clock_hz: float = 0.0
    start_offset_s: float = 0.0
    topics: tuple[str, ...] = ()
    wait_for_matched_s: float = 0.0
    namespace: str = DEFAULT_NAMESPACE


@dataclass
class PlayStats:
    """What was published."""

    messages: Counter[str] = field(default_factory=Counter)
    loops: int = 0
    clock_messages: int = 0
    refused: int = 0
    log_errors: list[str] = field(default_factory=list)


class Player:
    """Plays one log on `participant` (see the module docstring).

    Raises:
        RideLogError: the log cannot be opened, or the settings are unusable.
    """

    def __init__(self, path: str | Path, participant: DomainParticipant,
                 settings: PlaySettings = PlaySettings()) -> None:
        if not settings.rate > 0:
            raise RideLogError(f"{path}: playback rate must be > 0, got {settings.rate}")
        self.path = Path(path)
        if not self.path.is_file():
            raise RideLogError(f"{self.path}: no such ride log")
        self.participant = participant
        self.settings = settings
        self.stats = PlayStats()
        self._qos = {t.name(settings.namespace): t.qos for t in topics.TOPICS}
        self._writers: dict[tuple[str, str], RawWriter] = {}
        self._clock = (RawWriter(participant, CLOCK_TOPIC, CLOCK_TYPE, CLOCK_QOS)
                       if settings.clock_hz > 0 else None)
        self._clock_cls = typestore.types[CLOCK_TYPE]
        self._time_cls = typestore.types["builtin_interfaces/msg/Time"]

    def _writer(self, record: RawRecord) -> RawWriter | None:
        key = (record.topic, record.msgtype)
        writer = self._writers.get(key)
        if writer is None:
            if record.msgtype not in typestore.types or record.message_encoding != "cdr":
                log.warning("%s: cannot play %s (%s, %s)", self.path, record.topic,
                            record.msgtype or "no schema", record.message_encoding)
                self._writers[key] = writer = None  # type: ignore[assignment]
                return None
            writer = RawWriter(self.participant, record.topic, record.msgtype,
                               self._qos.get(record.topic, topics.RELIABLE_QOS))
            self._writers[key] = writer
        return writer

    def _wait_for_subscribers(self, stop: threading.Event) -> None:
        """Create the input topics' writers and wait until each has a reader."""
        inputs = [t for t in topics.INPUT_TOPICS
                  if not self.settings.topics or t.name(self.settings.namespace)
                  in self.settings.topics]
        writers = [RawWriter(self.participant, t.name(self.settings.namespace), t.msgtype,
                             t.qos) for t in inputs]
        for t, w in zip(inputs, writers, strict=True):
            self._writers[(t.name(self.settings.namespace), t.msgtype)] = w
        deadline = time.monotonic() + self.settings.wait_for_matched_s
        while time.monotonic() < deadline and not stop.is_set():
            if all(w.matched_count() > 0 for w in writers):
                return
            time.sleep(0.05)
        log.warning("%s: not every input topic has a subscriber; playing anyway", self.path)

    def _publish_clock(self, stamp_ns: int) -> None:
        assert self._clock is not None
        sec, nsec = divmod(stamp_ns, 1_000_000_000)
        self._clock.write(serialize(self._clock_cls(clock=self._time_cls(sec=sec,
                                                                          nanosec=nsec))))
        self.stats.clock_messages += 1

    def play(self, stop: threading.Event | None = None) -> PlayStats:
        """Publish the log (every loop of it) until the end or until `stop` is set.

        Raises:
            RideLogError: the file is not a ride log (damage inside is only counted).
        """
        stop = stop or threading.Event()
        if self.settings.wait_for_matched_s > 0:
            self._wait_for_subscribers(stop)
        while not stop.is_set():
            self._play_once(stop)
            self.stats.loops += 1
            if not self.settings.loop:
                break
        return self.stats

    def _play_once(self, stop: threading.Event) -> None:
        reader = RideLogReader(self.path, namespace=self.settings.namespace)
        rate = self.settings.rate
        clock_period_ns = int(1e9 / self.settings.clock_hz) if self._clock else 0
        start_log_ns: int | None = None
        start_wall_ns = 0
        next_clock_wall_ns = 0
        for record in reader.records():
            if start_log_ns is None:
                start_log_ns = record.log_time_ns + int(self.settings.start_offset_s * 1e9)
                start_wall_ns = time.monotonic_ns()
                next_clock_wall_ns = start_wall_ns
            if record.log_time_ns < start_log_ns:
                continue
            if self.settings.topics and record.topic not in self.settings.topics:
                continue
            due_wall_ns = start_wall_ns + int((record.log_time_ns - start_log_ns) / rate)
            while True:  # sleep until the message is due, publishing /clock meanwhile
                if stop.is_set():
                    return
                now = time.monotonic_ns()
                if self._clock is not None and now >= next_clock_wall_ns:
                    self._publish_clock(start_log_ns + int((now - start_wall_ns) * rate))
                    next_clock_wall_ns += clock_period_ns
                    if next_clock_wall_ns < now:  # fell behind: don't burst
                        next_clock_wall_ns = now + clock_period_ns
                if now >= due_wall_ns:
                    break
                wake = due_wall_ns if self._clock is None else min(due_wall_ns,
                                                                    next_clock_wall_ns)
                stop.wait(max(wake - now, 0) * 1e-9)
            writer = self._writer(record)
            if writer is None:
                continue
            try:
                writer.write(record.data)
            except Exception as err:  # noqa: BLE001  (Cyclone refuses bytes not of the type)
                self.stats.refused += 1
                log.warning("%s: %s at %.3f s refused by DDS (%s)", self.path, record.topic,
                            record.log_time_ns * 1e-9, err)
                continue
            self.stats.messages[record.topic] += 1
        self.stats.log_errors.extend(reader.errors)
