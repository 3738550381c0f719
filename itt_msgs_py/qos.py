"""QoS profiles as rosbag2 stores them with each recorded topic.

The MCAP `ros2` profile requires every channel to carry `offered_qos_profiles`: the YAML
list of the QoS profiles the topic's publishers offered, which `ros2 bag play` uses to
offer the same reliability and durability on replay (without it, sensor topics recorded
best-effort would come back reliable). The YAML is written with rosbags' rosbag2
metadata functions, in the string form of bag metadata version 9 (Jazzy); rosbags and
rosbag2 read it back.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache
from io import StringIO

from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2.metadata import dump_qos_v9
from ruamel.yaml import YAML

from itt_msgs_py.topics import QoS

#: The channel metadata key of the MCAP `ros2` profile.
OFFERED_QOS_KEY = "offered_qos_profiles"

# rmw's "unspecified" duration: deadline, lifespan and lease left to the middleware.
_UNSPECIFIED = QosTime(sec=0, nsec=0)


def to_rosbags(qos: QoS) -> Qos:
    """Our plain profile as a rosbags `Qos` (policies we do not set are the ROS defaults)."""
    return Qos(
        history=QosHistory[qos.history.name],
        depth=qos.depth,
        reliability=QosReliability[qos.reliability.name],
        durability=QosDurability[qos.durability.name],
        deadline=_UNSPECIFIED,
        lifespan=_UNSPECIFIED,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=_UNSPECIFIED,
        avoid_ros_namespace_conventions=False,
    )


@cache
def offered_qos_yaml(*profiles: QoS) -> str:
    """The `offered_qos_profiles` value for a topic whose publishers offered `profiles`
    (kept: a log writer asks for the same few profiles, and ruamel takes 50 ms each)."""
    return qos_yaml([to_rosbags(q) for q in profiles])


def qos_yaml(profiles: Sequence[Qos]) -> str:
    """The `offered_qos_profiles` value (rosbag2 metadata v9 YAML) of rosbags profiles."""
    stream = StringIO()
    yaml = YAML(typ="safe")
    yaml.default_flow_style = False
    yaml.dump(dump_qos_v9(list(profiles)), stream)
    return stream.getvalue().strip()

