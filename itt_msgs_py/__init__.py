"""ROS 2 messages of itt-planner without a ROS install.

Topic names and QoS (`topics`), the rosbags typestore with the custom `itt_msgs` types
read from the ROS interface package's `.msg` files (`definitions`), the CDR codec
(`codec`) and conversions to and from the core's types (`convert`).
"""

from __future__ import annotations

from itt_msgs_py.codec import deserialize, serialize
from itt_msgs_py.definitions import msgdef, typestore
from itt_msgs_py.topics import (
    ADVICE,
    DEFAULT_NAMESPACE,
    DIAGNOSTICS,
    GPS_FIX,
    INPUT_TOPICS,
    POWER,
    RELIABLE_QOS,
    SENSOR_QOS,
    SPEED,
    TARGET_LINE,
    TARGET_POWER,
    TOPICS,
    QoS,
    Topic,
    topics_by_name,
)

__all__ = [
    "ADVICE",
    "DEFAULT_NAMESPACE",
    "DIAGNOSTICS",
    "GPS_FIX",
    "INPUT_TOPICS",
    "POWER",
    "RELIABLE_QOS",
    "SENSOR_QOS",
    "SPEED",
    "TARGET_LINE",
    "TARGET_POWER",
    "TOPICS",
    "QoS",
    "Topic",
    "deserialize",
    "msgdef",
    "serialize",
    "topics_by_name",
    "typestore",
]
