"""Raw-payload DDS endpoints: CDR bytes in, CDR bytes out, under a ROS type's DDS name.

Cyclone's Python binding hands its C layer the serialised bytes of each sample; these
endpoints hand it rosbags' bytes directly (`ddspy_write` / `ddspy_take`), so no Python
object is built per sample and the wire bytes are exactly `itt_msgs_py.serialize`'s.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any, NamedTuple

from cyclonedds._clayer import ddspy_take, ddspy_write, ddspy_write_ts
from cyclonedds.core import DDSException, InstanceState, Listener, SampleState, ViewState
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from itt_msgs_py.topics import QoS
from itt_planner.dds.wire import WireQos, dds_topic_name, idl_struct

_ANY_STATE = SampleState.Any | ViewState.Any | InstanceState.Any
#: Samples taken per call; a reader's history depth bounds what is queued anyway.
TAKE_BATCH = 64


class Received(NamedTuple):
    """One sample as taken: CDR payload and the writer's source timestamp (ns)."""

    data: bytes
    source_timestamp_ns: int


class _TopicCache:
    """One DDS Topic per (participant, name): Cyclone refuses a second differing one."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._topics: dict[tuple[int, str, str], Topic[Any]] = {}

    def get(self, participant: DomainParticipant, ros_name: str, msgtype: str) -> Topic[Any]:
        key = (id(participant), ros_name, msgtype)
        with self._lock:
            topic = self._topics.get(key)
            if topic is None:
                topic = Topic(participant, dds_topic_name(ros_name), idl_struct(msgtype))
                self._topics[key] = topic
            return topic


_topics = _TopicCache()


class RawWriter:
    """A DataWriter publishing pre-serialised CDR payloads on a ROS topic.

    Raises:
        DDSException: Cyclone refused the topic or the writer.
    """

    def __init__(self, participant: DomainParticipant, ros_name: str, msgtype: str,
                 qos: QoS) -> None:
        self.ros_name = ros_name
        self.msgtype = msgtype
        self.topic = _topics.get(participant, ros_name, msgtype)
        self.writer = DataWriter(participant, self.topic, WireQos(qos).cyclone())

    def write(self, data: bytes, timestamp_ns: int | None = None) -> None:
        """Publish one payload.

        Raises:
            DDSException: Cyclone refused it (e.g. bytes that are not this type's CDR).
        """
        ret = (ddspy_write(self.writer._ref, data) if timestamp_ns is None
               else ddspy_write_ts(self.writer._ref, data, timestamp_ns))
        if ret < 0:
            raise DDSException(ret, f"writing {self.msgtype} on {self.ros_name}")

    def matched_count(self) -> int:
        """Number of matched DataReaders (local and remote)."""
        return len(self.writer.get_matched_subscriptions())


class RawReader:
    """A DataReader taking CDR payloads of a ROS topic; `on_data` runs on Cyclone's thread.

    Raises:
        DDSException: Cyclone refused the topic or the reader.
    """

    def __init__(self, participant: DomainParticipant, ros_name: str, msgtype: str,
                 qos: QoS, on_data: Callable[[], None] | None = None) -> None:
        self.ros_name = ros_name
        self.msgtype = msgtype
        self.topic = _topics.get(participant, ros_name, msgtype)
        listener = (Listener(on_data_available=lambda _reader: on_data())
                    if on_data is not None else None)
        self.reader = DataReader(participant, self.topic, WireQos(qos).cyclone(),
                                 listener=listener)

    def take(self, limit: int = TAKE_BATCH) -> list[Received]:
        """Up to `limit` queued samples, oldest first (invalid/dispose samples dropped).

        Raises:
            DDSException: the reader is gone.
        """
        ret = ddspy_take(self.reader._ref, _ANY_STATE, limit)
        if isinstance(ret, int):
            raise DDSException(ret, f"taking {self.msgtype} from {self.ros_name}")
        return [Received(bytes(data), info.source_timestamp) for data, info in ret
                if info.valid_data]

    def matched_count(self) -> int:
        """Number of matched DataWriters."""
        return len(self.reader.get_matched_publications())
