"""ROS 2 messages of itt-planner without a ROS install.

Topic names and QoS (`topics`), the sample registry of the input topics with their core
sample types and converters (`registry`), the rosbags typestore with the custom
`itt_msgs` types read from the ROS interface package's `.msg` files (`definitions`), the
CDR codec (`codec`) and conversions of the core's outputs (`convert`).
"""

from __future__ import annotations

from itt_msgs_py.codec import deserialize, serialize
from itt_msgs_py.definitions import msgdef, typestore
from itt_msgs_py.registry import (
    GPS_FIX,
    INPUT_TOPICS,
    POWER,
    SAMPLE_TOPICS,
    SPEED,
    TOPICS,
    SampleTopic,
    topics_by_name,
)
from itt_msgs_py.topics import (
    ADVICE,
    DEFAULT_NAMESPACE,
    DIAGNOSTICS,
    RELIABLE_QOS,
    SENSOR_QOS,
    TARGET_LINE,
    TARGET_POWER,
    QoS,
    Topic,
)

__all__ = [
    "ADVICE",
    "DEFAULT_NAMESPACE",
    "DIAGNOSTICS",
    "GPS_FIX",
    "INPUT_TOPICS",
    "POWER",
    "RELIABLE_QOS",
    "SAMPLE_TOPICS",
    "SENSOR_QOS",
    "SPEED",
    "TARGET_LINE",
    "TARGET_POWER",
    "TOPICS",
    "QoS",
    "SampleTopic",
    "Topic",
    "deserialize",
    "msgdef",
    "serialize",
    "topics_by_name",
    "typestore",
]
