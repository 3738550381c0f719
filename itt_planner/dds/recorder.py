"""Record DDS topics to an MCAP ride log as `ros2 bag record` does.

Topics are found through DDS discovery (the builtin publication topic): every ROS topic
(`rt/...`) whose type the itt typestore knows, or only the listed ones. Like rosbag2,
the reader is reliable when every writer seen offers reliable, else best-effort, so it
matches both kinds. Each message is stored as received (CDR bytes) with the full
`.msg` definition as schema; log time is the receive time on the wall clock, or on
`/clock` with `use_sim_time`; publish time is the writer's source timestamp.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
from cyclonedds.domain import DomainParticipant
from cyclonedds.qos import Policy

from itt_msgs_py import msgdef, topics, typestore
from itt_msgs_py.qos import offered_qos_yaml
from itt_planner.dds.endpoints import RawReader
from itt_planner.dds.wire import ros_topic_name, ros_type_name
from itt_planner.ridelog import MESSAGE_ENCODING, SCHEMA_ENCODING, RawRecord, RideLogWriter

log = logging.getLogger(__name__)

#: Deep enough for a burst between two takes; keep-last like rosbag2's subscriptions.
RECORD_DEPTH = 200
CLOCK_TOPIC = "/clock"


@dataclass(frozen=True)
class RecordSettings:
    """What to record.

    Attributes:
        topics: fully qualified topic names; empty with `all_topics`.
        all_topics: every discovered ROS topic of a known type.
        use_sim_time: log times from `/clock` (wall clock until the first one).
    """

    topics: tuple[str, ...] = ()
    all_topics: bool = False
    use_sim_time: bool = False


class Recorder:
    """Records to `output` until `stop` (see the module docstring).

    Raises:
        RideLogError: the output cannot be created.
        ValueError: neither topics nor `all_topics`.
    """

    def __init__(self, output: str | Path, participant: DomainParticipant,
                 settings: RecordSettings) -> None:
        if not settings.topics and not settings.all_topics:
            raise ValueError("record: name topics or use all_topics")
        self.settings = settings
        self.participant = participant
        self.writer = RideLogWriter(output)
        self.counts: Counter[str] = Counter()
        self._readers: dict[str, RawReader] = {}
        self._offered_qos: dict[str, str] = {}
        self._offered: dict[tuple[str, str], set[bool]] = {}
        self._data = threading.Event()
        self._discovery = BuiltinDataReader(participant, BuiltinTopicDcpsPublication)
        self._sim_ns = 0
        self._clock_reader: RawReader | None = None
        if settings.use_sim_time:
            self._clock_reader = RawReader(participant, CLOCK_TOPIC, "rosgraph_msgs/msg/Clock",
                                           topics.QoS(topics.Reliability.BEST_EFFORT, 1))

    def _wanted(self, topic: str) -> bool:
        return self.settings.all_topics or topic in self.settings.topics

    def _discover(self) -> None:
        for pub in self._discovery.take(N=100):
            if not getattr(pub, "topic_name", None) or not getattr(pub, "type_name", None):
                continue  # a disposed endpoint, or one without a topic (built-in)
            topic, msgtype = ros_topic_name(pub.topic_name), ros_type_name(pub.type_name)
            if topic is None or msgtype is None or not self._wanted(topic):
                continue
            if msgtype not in typestore.types:
                log.warning("record: skipping %s of unknown type %s", topic, msgtype)
                continue
            reliability = pub.qos[Policy.Reliability] if pub.qos is not None else None
            self._offered.setdefault((topic, msgtype), set()).add(
                isinstance(reliability, Policy.Reliability.Reliable))
            if topic not in self._readers:
                reliable = all(self._offered[(topic, msgtype)])
                qos = topics.QoS(topics.Reliability.RELIABLE if reliable
                                 else topics.Reliability.BEST_EFFORT, RECORD_DEPTH)
                self._readers[topic] = RawReader(self.participant, topic, msgtype, qos,
                                                 on_data=self._data.set)
                # Recorded as offered: ros2 bag play offers the same reliability again.
                self._offered_qos[topic] = offered_qos_yaml(qos)
                log.info("record: subscribed to %s [%s] (%s)", topic, msgtype,
                         "reliable" if reliable else "best effort")

    def _now_ns(self) -> int:
        if self._clock_reader is not None:
            for sample in self._clock_reader.take():
                clock = typestore.deserialize_cdr(sample.data, "rosgraph_msgs/msg/Clock").clock
                self._sim_ns = clock.sec * 1_000_000_000 + clock.nanosec
            if self._sim_ns:
                return self._sim_ns
        return time.time_ns()

    def _drain(self) -> None:
        for topic, reader in self._readers.items():
            received = reader.take()
            if not received:
                continue
            now = self._now_ns()
            schema = msgdef(reader.msgtype).encode()
            for sample in received:
                self.writer.write_raw(RawRecord(
                    topic=topic, msgtype=reader.msgtype, schema_encoding=SCHEMA_ENCODING,
                    schema_data=schema, message_encoding=MESSAGE_ENCODING,
                    log_time_ns=now, publish_time_ns=sample.source_timestamp_ns,
                    data=sample.data, offered_qos_profiles=self._offered_qos[topic]))
                self.counts[topic] += 1

    def run(self, stop: threading.Event, duration_s: float | None = None) -> Counter[str]:
        """Record until `stop` is set (or `duration_s` passed), then finish the file."""
        deadline = None if duration_s is None else time.monotonic() + duration_s
        try:
            while not stop.is_set() and (deadline is None or time.monotonic() < deadline):
                self._discover()
                self._drain()
                self._data.wait(0.1)
                self._data.clear()
            self._drain()
        finally:
            self.writer.close()
        return self.counts
