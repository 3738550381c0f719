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

"""Record ROS 2 topics to an MCAP ride log on real rclpy, as `ros2 bag record` does.

The ROS graph is polled every `DISCOVERY_PERIOD_S` (rosbag2's default polling
interval); each wanted topic that has a publisher gets a raw subscription (CDR bytes,
no decoding) that every offer can serve: reliable only if every publisher offers
reliable. Like `ros2 bag record -a`, `all_topics` takes every topic but the hidden ones
(a name part starting with `_`). Each message is written as received by the project's
writer (`RideLogWriter.write_raw`), with the full `.msg` definition as `ros2msg` schema
and the QoS its publishers offered, so `ros2 bag play` offers it again. Log time is the
receive time, on `/clock` with `use_sim_time` (the wall clock until the first `/clock`,
counted); publish time is the publisher's source timestamp.

A topic whose type has no generated class here (its package is not built) or no
definition in the itt typestore cannot be recorded: it is logged and listed in
`RecordStats.skipped`. A publisher that appears after the topic was subscribed keeps the
first subscription (and the first offers recorded), as with rosbag2.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from rosgraph_msgs.msg import Clock

from itt_msgs_py import msgdef, typestore
from itt_planner.logs.ridelog import MESSAGE_ENCODING, SCHEMA_ENCODING, RawRecord
from itt_planner.logs.ridelog_writer import RideLogWriter
from itt_planner_ros.ros_types import (
    RosTypeError,
    edge_node,
    message_class,
    offers_yaml,
    request_qos,
)

log = logging.getLogger(__name__)

NODE_NAME = 'itt_recorder'
#: rosbag2's default `--polling-interval`: how soon a new topic is subscribed.
DISCOVERY_PERIOD_S = 0.1
#: Keep-last depth of the subscriptions: a burst between two executor turns fits.
RECORD_DEPTH = 200
#: After the stop, what is already queued is still written, for at most this long.
DRAIN_LIMIT_S = 1.0
CLOCK_TOPIC = '/clock'
#: rclcpp::ClockQoS, as a node with `use_sim_time` subscribes to `/clock`.
CLOCK_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)


@dataclass(frozen=True)
class RecordSettings:
    """What to record.

    Attributes:
        topics: fully qualified topic names (a name without `/` is taken from the
            root); empty with `all_topics`.
        all_topics: every topic of the graph but the hidden ones, as they appear.
        use_sim_time: log times from `/clock`.
    """

    topics: tuple[str, ...] = ()
    all_topics: bool = False
    use_sim_time: bool = False


@dataclass
class RecordStats:
    """What was recorded, and what was not.

    Attributes:
        messages: messages written, per topic.
        offered_qos: the `offered_qos_profiles` recorded for each topic.
        skipped: topics seen but not recorded, with the reason.
        wall_clock_stamped: with `use_sim_time`, messages logged at wall-clock time
            because no `/clock` had arrived yet.
    """

    messages: Counter[str] = field(default_factory=Counter)
    offered_qos: dict[str, str] = field(default_factory=dict)
    skipped: dict[str, str] = field(default_factory=dict)
    wall_clock_stamped: int = 0

    def as_dict(self) -> dict[str, Any]:
        """Plain JSON-able values (the CLI's `--json` output)."""
        return {'messages': dict(self.messages), 'recorded': self.messages.total(),
                'offered_qos': dict(self.offered_qos), 'skipped': dict(self.skipped),
                'wall_clock_stamped': self.wall_clock_stamped}


def record(output: str | Path, settings: RecordSettings,
           stop_event: threading.Event | None = None, duration_s: float | None = None, *,
           context: Context | None = None) -> RecordStats:
    """Record to `output` until `stop_event` is set or `duration_s` (wall) passed.

    The file is finished (summary, indexes) whatever ends the recording, including an
    error; messages already queued when the stop comes are still written. With
    `context=None` the recorder runs on a context of its own (initialised and shut down
    here, no rclpy signal handlers: set `stop_event` from yours); otherwise on the given,
    initialised context, which is left running.

    Raises:
        ValueError: neither topics nor `all_topics`.
        RideLogError: the output cannot be created.
    """
    if not settings.topics and not settings.all_topics:
        raise ValueError('record: name topics or use all_topics')
    stop = stop_event or threading.Event()
    deadline = None if duration_s is None else time.monotonic() + duration_s
    with RideLogWriter(output) as writer, edge_node(NODE_NAME, context) as node:
        recorder = _Recorder(node, writer, settings)
        executor = SingleThreadedExecutor(context=node.context)
        executor.add_node(node)
        try:
            next_poll = 0.0
            while not stop.is_set() and (deadline is None or time.monotonic() < deadline):
                if time.monotonic() >= next_poll:
                    recorder.discover()
                    next_poll = time.monotonic() + DISCOVERY_PERIOD_S
                executor.spin_once(timeout_sec=DISCOVERY_PERIOD_S / 2)
            _drain(executor, recorder.stats)
        finally:
            executor.shutdown()
        return recorder.stats


def _drain(executor: SingleThreadedExecutor, stats: RecordStats) -> None:
    """Write what is queued: spin until two turns in a row bring no message."""
    limit = time.monotonic() + DRAIN_LIMIT_S
    idle = 0
    while idle < 2 and time.monotonic() < limit:
        before = stats.messages.total()
        executor.spin_once(timeout_sec=0.01)
        idle = idle + 1 if stats.messages.total() == before else 0


def _hidden(topic: str) -> bool:
    return any(part.startswith('_') for part in topic.split('/'))


class _Recorder:
    """The subscriptions, and the writing of what they receive."""

    def __init__(self, node: Node, writer: RideLogWriter, settings: RecordSettings) -> None:
        self.node = node
        self.writer = writer
        self.settings = settings
        self.stats = RecordStats()
        self._wanted = {t if t.startswith('/') else f'/{t}' for t in settings.topics}
        self._subscriptions: dict[str, Any] = {}
        # The ROS time under `use_sim_time`, from `/clock`. Kept here rather than by the
        # node's time source so that a recorded `/clock` message sets the time before it
        # is logged (two subscriptions would race); the recording subscription of
        # `/clock` replaces this one.
        self._sim_time_ns = 0
        self._clock_subscription = (node.create_subscription(
            Clock, CLOCK_TOPIC, self._on_clock, CLOCK_QOS, raw=True)
            if settings.use_sim_time else None)

    def discover(self) -> None:
        """Subscribe to the wanted topics that appeared since the last look."""
        for topic, types in self.node.get_topic_names_and_types():
            if topic in self._subscriptions or topic in self.stats.skipped:
                continue
            if not (topic in self._wanted or (self.settings.all_topics and not _hidden(topic))):
                continue
            offers = [info.qos_profile
                      for info in self.node.get_publishers_info_by_topic(topic)]
            if not offers:
                continue  # only subscribers so far: wait for a publisher
            self._subscribe(topic, types, offers)

    def _subscribe(self, topic: str, types: list[str], offers: list[Any]) -> None:
        if len(types) != 1:
            self._skip(topic, f'published with several types {types}')
            return
        msgtype = types[0]
        if msgtype not in typestore.fielddefs:
            self._skip(topic, f'{msgtype} has no message definition in the itt typestore')
            return
        try:
            cls = message_class(msgtype)
        except RosTypeError as err:
            self._skip(topic, str(err))
            return
        qos = request_qos(offers, RECORD_DEPTH)
        offered = offers_yaml(offers)
        schema = msgdef(msgtype).encode()

        def write(data: bytes, info: dict[str, Any]) -> None:
            if topic == CLOCK_TOPIC and self.settings.use_sim_time:
                self._on_clock(data)
            self.writer.write_raw(RawRecord(
                topic=topic, msgtype=msgtype, schema_encoding=SCHEMA_ENCODING,
                schema_data=schema, message_encoding=MESSAGE_ENCODING,
                log_time_ns=self._log_time_ns(topic, info),
                publish_time_ns=info.get('source_timestamp') or 0, data=data,
                offered_qos_profiles=offered))
            self.stats.messages[topic] += 1

        # rclpy hands a two-argument callback the message info too (not in its hints).
        self._subscriptions[topic] = self.node.create_subscription(
            cls, topic, write, qos, raw=True)  # type: ignore[arg-type]
        if topic == CLOCK_TOPIC and self._clock_subscription is not None:
            self.node.destroy_subscription(self._clock_subscription)
            self._clock_subscription = None
        self.stats.offered_qos[topic] = offered
        log.info('record: subscribed to %s [%s] (%s)', topic, msgtype,
                 qos.reliability.name.lower())

    def _skip(self, topic: str, reason: str) -> None:
        self.stats.skipped[topic] = reason
        log.warning('record: not recording %s: %s', topic, reason)

    def _on_clock(self, data: bytes) -> None:
        stamp = deserialize_message(data, Clock).clock
        self._sim_time_ns = stamp.sec * 1_000_000_000 + stamp.nanosec

    def _log_time_ns(self, topic: str, info: dict[str, Any]) -> int:
        if self.settings.use_sim_time:
            if self._sim_time_ns > 0:
                return self._sim_time_ns
            self.stats.wall_clock_stamped += 1
            if self.stats.wall_clock_stamped == 1:
                log.warning('record: use_sim_time and no /clock yet: logging %s at wall '
                            'time', topic)
            return time.time_ns()
        return info.get('received_timestamp') or time.time_ns()
