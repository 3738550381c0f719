# Copyright 2026 itt-planner team
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""Play a ride log on real rclpy, as `ros2 bag play` does (rate, loop, offset, /clock).

Every message goes out as its stored CDR bytes (`publish(bytes)`, no decoding) on its
topic at its log time scaled by `rate`, with the QoS its publishers offered when it was
recorded (`offered_qos_profiles`, read as `ros2 bag play` reads it), or, for a channel
without that record, the interface's QoS of a known topic and ROS 2's default otherwise.
All publishers are created before the first message, so subscribers can match first
(`wait_for_matched_s` waits for them, then `MATCH_SETTLE_S` more, and `delay_s` holds the
first message back further, as `ros2 bag play --delay` does). With `clock_hz` the
playback time is published on `/clock` (rosgraph_msgs/Clock, clock QoS) for nodes
running with `use_sim_time`, from the start time while waiting for subscribers and
during the delay.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, NamedTuple

from builtin_interfaces.msg import Time
from mcap.reader import make_reader
from rclpy.context import Context
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosbags.rosbag2.errors import ReaderError
from rosgraph_msgs.msg import Clock

from itt_msgs_py import DEFAULT_NAMESPACE, registry, topics
from itt_msgs_py.qos import OFFERED_QOS_KEY
from itt_planner.errors import RideLogError
from itt_planner.logs.ridelog import MESSAGE_ENCODING, RideLogReader
from itt_planner_ros.ros_types import (
    DEFAULT_QOS,
    RosTypeError,
    edge_node,
    message_class,
    replay_qos,
)

log = logging.getLogger(__name__)

NODE_NAME = 'itt_player'
CLOCK_TOPIC = '/clock'
#: rclcpp::ClockQoS, what `ros2 bag play --clock` offers: best effort, keep last 1.
CLOCK_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
#: Waiting for subscribers, play this long after the last one matched: a publisher can
#: see a subscriber before that subscriber knows the publisher, and best-effort messages
#: sent in between are dropped by the subscriber.
MATCH_SETTLE_S = 0.25
#: While holding, how often the subscriber counts are polled (and, at most, `/clock` sent).
HOLD_STEP_S = 0.02


@dataclass(frozen=True)
class PlaySettings:
    """How to play a log.

    Attributes:
        rate: playback speed factor (2.0 = twice as fast).
        loop: start over at the end, until stopped.
        clock_hz: publish `/clock` at this wall-clock rate; 0 for no clock.
        start_offset_s: skip the first seconds of the log.
        topics: only these topics (fully qualified); empty for all.
        wait_for_matched_s: before playing, wait up to this long for every played pacing
            input topic, and `/clock` with `clock_hz`, to have a subscriber (0: start at
            once, like `ros2 bag play`).
        delay_s: then hold the first message back this long (`ros2 bag play --delay`),
            once, not before each loop. The wait sees the player's side only: a
            subscriber whose side has not matched yet drops what comes first, and any
            subscriber of a topic (a recorder's) ends the wait for it (a node lost its
            first messages, up to 4 fixes, in 9 of 78 pipeline tests at load ~10 on 2
            cores, 2026-12-03). `/clock` holds the start time meanwhile (rosbag2
            publishes none during its delay), so a `use_sim_time` node has a time
            before its inputs.
        namespace: namespace of the pacing topics in the log (for their QoS).
    """

    rate: float = 1.0
    loop: bool = False
    clock_hz: float = 0.0
    start_offset_s: float = 0.0
    topics: tuple[str, ...] = ()
    wait_for_matched_s: float = 0.0
    delay_s: float = 0.0
    namespace: str = DEFAULT_NAMESPACE


@dataclass
class PlayStats:
    """What was published, and what was not.

    Attributes:
        messages: messages published, per topic.
        loops: complete passes over the log.
        clock_messages: `/clock` messages published.
        unplayable: messages not published because their type has no generated class
            here or is not CDR, per topic (each topic also logged once).
        refused: messages the middleware refused to publish.
        unmatched: topics that still had no subscriber when `wait_for_matched_s` ran out.
        log_errors: damage found in the log (what was readable was played).
    """

    messages: Counter[str] = field(default_factory=Counter)
    loops: int = 0
    clock_messages: int = 0
    unplayable: Counter[str] = field(default_factory=Counter)
    refused: int = 0
    unmatched: list[str] = field(default_factory=list)
    log_errors: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        """Plain JSON-able values (the CLI's `--json` output)."""
        return {'messages': dict(self.messages), 'published': self.messages.total(),
                'loops': self.loops, 'clock_messages': self.clock_messages,
                'unplayable': dict(self.unplayable), 'refused': self.refused,
                'unmatched': list(self.unmatched), 'log_errors': list(self.log_errors)}


class _Channel(NamedTuple):
    topic: str
    msgtype: str
    message_encoding: str
    offered_qos: str


#: Seconds the player waits, after the last message, for it to reach its readers.
LINGER_S = 0.5

def play(log_path: str | Path, settings: PlaySettings = PlaySettings(),
         stop_event: threading.Event | None = None, *,
         context: Context | None = None) -> PlayStats:
    """Publish the log (every loop of it) until its end or until `stop_event` is set.

    With `context=None` the player runs on a context of its own (initialised and shut
    down here, no rclpy signal handlers: set `stop_event` from yours); otherwise on the
    given, initialised context, which is left running.

    Raises:
        RideLogError: the log is missing or not an MCAP file, or the settings are
            unusable (damage inside the log is only counted in `log_errors`).
    """
    path = Path(log_path)
    if not settings.rate > 0:
        raise RideLogError(f'{path}: playback rate must be > 0, got {settings.rate}')
    if not settings.delay_s >= 0:
        raise RideLogError(f'{path}: the delay must be >= 0 s, got {settings.delay_s}')
    if not path.is_file():
        raise RideLogError(f'{path}: no such ride log')
    stop = stop_event or threading.Event()
    channels = _channels(path, settings.namespace)
    with edge_node(NODE_NAME, context) as node:
        player = _Player(path, node, settings, channels)
        if settings.wait_for_matched_s > 0:
            player.wait_for_subscribers(stop)
        player.hold(stop, time.monotonic() + settings.delay_s)
        while player.play_once(stop):
            player.stats.loops += 1
            if not settings.loop:
                break
        player.linger()
        return player.stats


def _first_log_time_ns(path: Path) -> int:
    """Log time of the first message (0 for a log without any)."""
    return next((r.log_time_ns for r in RideLogReader(path).records()), 0)


def _channels(path: Path, namespace: str) -> list[_Channel]:
    """The log's channels, from its summary; a log without one is read through."""
    try:
        with path.open('rb') as file:
            summary = make_reader(file).get_summary()
    except Exception:  # noqa: BLE001  (cut-off or damaged summary: read the records)
        summary = None
    if summary is not None:
        return [_Channel(c.topic, s.name if (s := summary.schemas.get(c.schema_id)) else '',
                         c.message_encoding, c.metadata.get(OFFERED_QOS_KEY, ''))
                for c in summary.channels.values()]
    found = {(r.topic, r.msgtype): _Channel(r.topic, r.msgtype, r.message_encoding,
                                            r.offered_qos_profiles)
             for r in RideLogReader(path, namespace=namespace).records()}
    return list(found.values())


class _Player:
    """The publishers of one log, and the pacing of its messages."""

    def __init__(self, path: Path, node: Node, settings: PlaySettings,
                 channels: list[_Channel]) -> None:
        self.path = path
        self.node = node
        self.settings = settings
        self.stats = PlayStats()
        known = registry.topics_by_name(settings.namespace)
        self._publishers: dict[tuple[str, str], Any] = {}
        for channel in channels:
            if settings.topics and channel.topic not in settings.topics:
                continue
            self._publishers[(channel.topic, channel.msgtype)] = self._publisher(
                channel, known[channel.topic].qos if channel.topic in known else DEFAULT_QOS)
        self._clock = (node.create_publisher(Clock, CLOCK_TOPIC, CLOCK_QOS)
                       if settings.clock_hz > 0 else None)
        self._hold_period_s = (min(1.0 / settings.clock_hz, HOLD_STEP_S) if self._clock
                               else HOLD_STEP_S)
        absent = sorted(set(settings.topics) - {c.topic for c in channels})
        if absent:
            log.warning('%s: no messages on %s in this log', path, ', '.join(absent))

    def _publisher(self, channel: _Channel, fallback: topics.QoS) -> Any | None:
        """The channel's publisher; None (logged) when it cannot be played here."""
        if channel.message_encoding != MESSAGE_ENCODING:
            log.warning('%s: cannot play %s: %s messages, not %s', self.path, channel.topic,
                        channel.message_encoding, MESSAGE_ENCODING)
            return None
        try:
            cls = message_class(channel.msgtype)
        except RosTypeError as err:
            log.warning('%s: cannot play %s: %s', self.path, channel.topic, err)
            return None
        try:
            qos = replay_qos(channel.offered_qos, fallback)
        except (ReaderError, KeyError, TypeError) as err:  # bad YAML, missing fields
            log.warning('%s: %s: unreadable offered QoS (%s); playing with %s', self.path,
                        channel.topic, err, fallback)
            qos = replay_qos('', fallback)
        return self.node.create_publisher(cls, channel.topic, qos)

    def wait_for_subscribers(self, stop: threading.Event) -> None:
        """Wait until each played pacing input topic, and `/clock` when it is published,
        has a subscriber, or time is up; `/clock` holds the start time meanwhile."""
        inputs = {t.name(self.settings.namespace) for t in registry.INPUT_TOPICS}
        waiting = {topic: pub for (topic, _), pub in self._publishers.items()
                   if pub is not None and topic in inputs}
        if self._clock is not None:  # else a sim-time node's first inputs have no time
            waiting[CLOCK_TOPIC] = self._clock
        deadline = time.monotonic() + self.settings.wait_for_matched_s
        while not stop.is_set() and time.monotonic() < deadline:
            if all(p.get_subscription_count() > 0 for p in waiting.values()):
                self.hold(stop, time.monotonic() + MATCH_SETTLE_S)
                return
            self.hold(stop, min(time.monotonic() + HOLD_STEP_S, deadline))
        self.stats.unmatched = sorted(t for t, p in waiting.items()
                                      if p.get_subscription_count() == 0)
        if self.stats.unmatched:
            log.warning('%s: no subscriber on %s after %.1f s; playing anyway', self.path,
                        ', '.join(self.stats.unmatched), self.settings.wait_for_matched_s)

    def hold(self, stop: threading.Event, until: float) -> None:
        """Publish nothing until `until` (monotonic s) but `/clock` at the start time."""
        while not stop.is_set() and (now := time.monotonic()) < until:
            if self._clock is not None:
                self._publish_clock(self._start_ns)
            stop.wait(min(until - now, self._hold_period_s))

    @cached_property
    def _start_ns(self) -> int:
        """The playback's start time: the log's first, plus the start offset."""
        return _first_log_time_ns(self.path) + int(self.settings.start_offset_s * 1e9)

    def _publish_clock(self, stamp_ns: int) -> None:
        assert self._clock is not None
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        self._clock.publish(Clock(clock=Time(sec=sec, nanosec=nanosec)))
        self.stats.clock_messages += 1

    def linger(self) -> None:
        """Let the last messages reach their readers before the publishers go: reliable
        ones until acknowledged (as rosbag2's player waits for acks), best-effort ones for
        a moment (a run that destroyed them at once lost the log's last message)."""
        for publisher in self._publishers.values():
            publisher.wait_for_all_acked(Duration(seconds=LINGER_S))
        time.sleep(LINGER_S)

    def play_once(self, stop: threading.Event) -> bool:
        """One pass over the log, paced on the monotonic clock; False if stopped."""
        reader = RideLogReader(self.path, namespace=self.settings.namespace)
        rate = self.settings.rate
        clock_period_ns = int(1e9 / self.settings.clock_hz) if self._clock else 0
        start_log_ns = self._start_ns
        start_wall_ns = next_clock_wall_ns = time.monotonic_ns()
        for record in reader.records():
            if record.log_time_ns < start_log_ns:
                continue
            key = (record.topic, record.msgtype)
            if key not in self._publishers:  # a topic not selected with `topics`
                continue
            due_wall_ns = start_wall_ns + int((record.log_time_ns - start_log_ns) / rate)
            while True:  # sleep until the message is due, publishing /clock meanwhile
                if stop.is_set():
                    return False
                now = time.monotonic_ns()
                if self._clock is not None and now >= next_clock_wall_ns:
                    self._publish_clock(start_log_ns + int((now - start_wall_ns) * rate))
                    next_clock_wall_ns += clock_period_ns
                    if next_clock_wall_ns < now:  # fell behind: don't burst
                        next_clock_wall_ns = now + clock_period_ns
                if now >= due_wall_ns:
                    break
                wake = (due_wall_ns if self._clock is None
                        else min(due_wall_ns, next_clock_wall_ns))
                stop.wait(max(wake - now, 0) * 1e-9)
            publisher = self._publishers[key]
            if publisher is None:
                self.stats.unplayable[record.topic] += 1
                continue
            try:
                publisher.publish(record.data)
            except Exception as err:  # noqa: BLE001  (rclpy raises RCLError and others)
                self.stats.refused += 1
                log.warning('%s: %s at %.3f s refused (%s)', self.path, record.topic,
                            record.log_time_ns * 1e-9, err)
                continue
            self.stats.messages[record.topic] += 1
        self.stats.log_errors.extend(reader.errors)
        return not stop.is_set()
