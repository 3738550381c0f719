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

"""What the rclpy edge (node, player, recorder) shares: types, QoS, a node of its own.

- `message_class`: the generated class of `pkg/msg/Name`, by importlib of `pkg.msg`
  (what `rosidl_runtime_py.utilities.get_message` does; that package is not on PyPI).
- `qos_profile`: the interface's plain QoS (`itt_msgs_py.topics.QoS`) as a QoSProfile.
- `offers_yaml` / `replay_qos` / `request_qos`: QoS as rosbag2 records and uses it.
  The recorder stores what each publisher offered, as the graph reports it (Fast DDS does
  not send history and depth: `history: unknown, depth: 0`, as in rosbag2's own bags);
  the player offers the recorded reliability and durability again; the recorder asks for
  what every offer can serve.
- `edge_node`: a node on a context of its own (or a given one), shut down on exit, with
  no rclpy signal handlers: the caller's stop event decides when to stop.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import rclpy
from rclpy.context import Context
from rclpy.duration import Duration, Infinite
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2.metadata import parse_qos

from itt_msgs_py import topics
from itt_msgs_py.qos import qos_yaml
from itt_planner.errors import IttError

#: ROS 2's default profile (reliable, volatile, keep last 10): rosbag2 plays a topic
#: with it when the log recorded no offer or offers that disagree.
DEFAULT_QOS = topics.RELIABLE_QOS
#: Recorded durations at or above this many seconds are "infinite" (Humble's bags write
#: 2147483647 s, Jazzy's 9223372036 s).
_INFINITE_SEC = 2**31 - 1


class RosTypeError(IttError):
    """A ROS message type has no generated Python class here (names the type)."""


def message_class(msgtype: str) -> Any:
    """Return the generated Python class of `pkg/msg/Name` (or `pkg/Name`).

    Raises:
        RosTypeError: the name is not a message type name, or its package is not built
            (e.g. `itt_msgs` before the interface package was generated).
    """
    parts = msgtype.split('/')
    if len(parts) == 2:
        parts.insert(1, 'msg')
    if len(parts) != 3 or parts[1] != 'msg' or not all(parts):
        raise RosTypeError(f'{msgtype!r} is not a message type name (pkg/msg/Name)')
    package, _, name = parts
    try:
        module = importlib.import_module(f'{package}.msg')
    except ImportError as err:
        raise RosTypeError(f'{msgtype}: no generated Python package {package}.msg '
                           f'({err})') from None
    cls = getattr(module, name, None)
    if cls is None:
        raise RosTypeError(f'{msgtype}: {package}.msg has no message {name}')
    return cls


def qos_profile(qos: topics.QoS) -> QoSProfile:
    """Return the QoSProfile of a topic's plain QoS."""
    return QoSProfile(
        depth=qos.depth,
        reliability=(ReliabilityPolicy.BEST_EFFORT
                     if qos.reliability is topics.Reliability.BEST_EFFORT
                     else ReliabilityPolicy.RELIABLE),
        history=(HistoryPolicy.KEEP_ALL if qos.history is topics.History.KEEP_ALL
                 else HistoryPolicy.KEEP_LAST),
        durability=(DurabilityPolicy.TRANSIENT_LOCAL
                    if qos.durability is topics.Durability.TRANSIENT_LOCAL
                    else DurabilityPolicy.VOLATILE),
    )


def _qos_time(duration: Duration) -> QosTime:
    sec, nsec = divmod(duration.nanoseconds, 1_000_000_000)
    return QosTime(sec=sec, nsec=nsec)


def _duration(time: QosTime) -> Duration:
    if time.sec >= _INFINITE_SEC:
        return Infinite
    return Duration(seconds=time.sec, nanoseconds=time.nsec)


def offers_yaml(offers: Sequence[QoSProfile]) -> str:
    """The `offered_qos_profiles` value (rosbag2 metadata v9 YAML) of these offers."""
    profiles = [Qos(
        history=QosHistory[p.history.name], depth=p.depth,
        reliability=QosReliability[p.reliability.name],
        durability=QosDurability[p.durability.name],
        deadline=_qos_time(p.deadline), lifespan=_qos_time(p.lifespan),
        liveliness=QosLiveliness[p.liveliness.name],
        liveliness_lease_duration=_qos_time(p.liveliness_lease_duration),
        avoid_ros_namespace_conventions=p.avoid_ros_namespace_conventions,
    ) for p in offers]
    return qos_yaml(profiles)


def _agreed(values: Sequence[Any], allowed: Sequence[Any], default: Any) -> Any:
    """The value every offer agrees on, if it is one of `allowed`; else `default`."""
    agreed = all(v == values[0] for v in values) and values[0] in allowed
    return values[0] if agreed else default


def replay_qos(offered_yaml: str, fallback: topics.QoS = DEFAULT_QOS) -> QoSProfile:
    """The profile to play a recorded topic with, as `ros2 bag play` picks it.

    Reliability, durability, deadline, lifespan and liveliness are the recorded offers'
    when they all agree, else the default profile's; keep-last with the largest recorded
    depth (the default's when the graph did not report one). No recorded offer: the
    `fallback` profile (the interface's QoS for a known topic).

    Raises:
        rosbags.rosbag2.errors.ReaderError: the YAML is not readable.
    """
    offers = parse_qos(offered_yaml) if offered_yaml else []
    if not offers:
        return qos_profile(fallback)
    default = qos_profile(DEFAULT_QOS)
    depths = [o.depth for o in offers if o.history is QosHistory.KEEP_LAST and o.depth > 0]
    reliability = _agreed([o.reliability.name for o in offers], ('RELIABLE', 'BEST_EFFORT'),
                          default.reliability.name)
    durability = _agreed([o.durability.name for o in offers], ('VOLATILE', 'TRANSIENT_LOCAL'),
                         default.durability.name)
    liveliness = _agreed([o.liveliness.name for o in offers], ('AUTOMATIC', 'MANUAL_BY_TOPIC'),
                         default.liveliness.name)
    deadlines = [_duration(o.deadline) for o in offers]
    lifespans = [_duration(o.lifespan) for o in offers]
    leases = [_duration(o.liveliness_lease_duration) for o in offers]
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=max(depths, default=default.depth),
        reliability=ReliabilityPolicy[reliability], durability=DurabilityPolicy[durability],
        liveliness=LivelinessPolicy[liveliness],
        deadline=_agreed(deadlines, deadlines[:1], default.deadline),
        lifespan=_agreed(lifespans, lifespans[:1], default.lifespan),
        liveliness_lease_duration=_agreed(leases, leases[:1],
                                          default.liveliness_lease_duration))


def request_qos(offers: Sequence[QoSProfile], depth: int) -> QoSProfile:
    """A subscription profile every offer can serve (rosbag2's rule).

    Reliable only when every publisher offers reliable, transient-local only when every
    one does; keep-last `depth`.
    """
    reliable = bool(offers) and all(
        o.reliability is ReliabilityPolicy.RELIABLE for o in offers)
    latched = bool(offers) and all(
        o.durability is DurabilityPolicy.TRANSIENT_LOCAL for o in offers)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=(DurabilityPolicy.TRANSIENT_LOCAL if latched
                    else DurabilityPolicy.VOLATILE))


@contextmanager
def edge_node(name: str, context: Context | None = None) -> Iterator[Node]:
    """A node for a tool (player, recorder, benchmark), destroyed on exit.

    With `context=None` the node gets a context of its own, initialised from the
    environment (`ROS_DOMAIN_ID`, `ROS_AUTOMATIC_DISCOVERY_RANGE`, Fast DDS profiles)
    without rclpy's signal handlers, and shut down on exit; a given context is left to
    its owner. The node has no parameter services and no `/rosout` publisher: tools log
    through Python's `logging`.
    """
    own = context is None
    if own:
        context = Context()
        rclpy.init(context=context)
    assert context is not None
    try:
        node = rclpy.create_node(name, context=context, enable_rosout=False,
                                 start_parameter_services=False)
        try:
            yield node
        finally:
            node.destroy_node()
    finally:
        if own:
            context.try_shutdown()
