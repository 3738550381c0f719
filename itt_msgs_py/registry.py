"""The sample registry: each input topic with its core sample type and converters.

One `SampleTopic` per sensor names its topic (key, ROS message type, QoS), the core
sample type (`itt_planner.live.samples`) and the two converters, message -> sample and
sample -> message. Everything that handles inputs goes through this one table, never a
per-type branch: the pacing node subscribes to its topics in one loop, the ride log
writes a sample with `sample_to_msg` and reads one back with `to_core`, the replay tells
samples from other records with `is_sample`, the player waits for subscribers on
`INPUT_TOPICS`. `TOPICS` is every topic of the interface (these inputs and the outputs of
`topics`).

Adding a sensor (say heart rate): a `.msg` if no standard type fits, one entry here with
its two converters, its sample type in `itt_planner.live.samples`, one estimator hook
(`StateEstimator`) and one Rerun view (`RideRecorder`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeGuard, TypeVar

import numpy as np

from itt_msgs_py.convert import BASE_FRAME, GPS_FRAME, from_time, header, output_to_core
from itt_msgs_py.definitions import msgdef, typestore
from itt_msgs_py.qos import offered_qos_yaml
from itt_msgs_py.topics import (
    DEFAULT_NAMESPACE,
    OUTPUT_TOPICS,
    SENSOR_QOS,
    Direction,
    Topic,
)
from itt_planner.live.samples import GpsFix, PowerReading, Sample, WheelSpeed

# The rosbags classes of the input messages (their constants are not in the type hints).
_T: Any = typestore.types
NavSatFix = _T["sensor_msgs/msg/NavSatFix"]
NavSatStatus = _T["sensor_msgs/msg/NavSatStatus"]
TwistStamped = _T["geometry_msgs/msg/TwistStamped"]
Twist = _T["geometry_msgs/msg/Twist"]
Vector3 = _T["geometry_msgs/msg/Vector3"]
PowerStamped = _T["itt_msgs/msg/PowerStamped"]

S = TypeVar("S")


@dataclass(frozen=True)
class SampleTopic(Generic[S]):
    """One input of the interface: its topic, its core sample type and the converters."""

    topic: Topic
    sample_type: type[S]
    to_sample: Callable[[Any], S]
    to_msg: Callable[[S], Any]


# --- the converters ----------------------------------------------------------------------

def gps_fix_to_msg(fix: GpsFix) -> Any:
    """`sensor_msgs/NavSatFix`; a known `std_m` becomes an approximated diagonal covariance."""
    known = math.isfinite(fix.std_m)
    var = fix.std_m**2 if known else 0.0
    # Vertical GNSS error is typically about 1.5x the horizontal one.
    cov = np.array([var, 0, 0, 0, var, 0, 0, 0, (1.5**2) * var], dtype=np.float64)
    return NavSatFix(
        header=header(fix.stamp_s, GPS_FRAME),
        status=NavSatStatus(status=NavSatStatus.STATUS_FIX, service=NavSatStatus.SERVICE_GPS),
        latitude=fix.lat_deg, longitude=fix.lon_deg, altitude=fix.alt_m,
        position_covariance=cov,
        position_covariance_type=(NavSatFix.COVARIANCE_TYPE_APPROXIMATED if known
                                  else NavSatFix.COVARIANCE_TYPE_UNKNOWN),
    )


def msg_to_gps_fix(msg: Any) -> GpsFix:
    """`GpsFix` of a `NavSatFix`; `std_m` is NaN when the covariance is unknown."""
    known = msg.position_covariance_type != NavSatFix.COVARIANCE_TYPE_UNKNOWN
    std = math.sqrt(0.5 * (msg.position_covariance[0] + msg.position_covariance[4]))
    return GpsFix(stamp_s=from_time(msg.header.stamp), lat_deg=msg.latitude,
                  lon_deg=msg.longitude, alt_m=msg.altitude, std_m=std if known else math.nan)


def wheel_speed_to_msg(sample: WheelSpeed) -> Any:
    """`geometry_msgs/TwistStamped` with the wheel speed in `twist.linear.x` (m/s)."""
    zero = Vector3(x=0.0, y=0.0, z=0.0)
    return TwistStamped(
        header=header(sample.stamp_s, BASE_FRAME),
        twist=Twist(linear=Vector3(x=sample.speed_mps, y=0.0, z=0.0), angular=zero),
    )


def msg_to_wheel_speed(msg: Any) -> WheelSpeed:
    """`WheelSpeed` of a `TwistStamped`."""
    return WheelSpeed(stamp_s=from_time(msg.header.stamp), speed_mps=msg.twist.linear.x)


def power_reading_to_msg(sample: PowerReading) -> Any:
    """`itt_msgs/PowerStamped`."""
    return PowerStamped(header=header(sample.stamp_s, BASE_FRAME), power_w=sample.power_w,
                        cadence_rpm=sample.cadence_rpm)


def msg_to_power_reading(msg: Any) -> PowerReading:
    """`PowerReading` of a `PowerStamped`."""
    return PowerReading(stamp_s=from_time(msg.header.stamp), power_w=msg.power_w,
                        cadence_rpm=msg.cadence_rpm)


# --- the table -----------------------------------------------------------------------------

GPS_FIX = Topic("gps/fix", "sensor_msgs/msg/NavSatFix", SENSOR_QOS, Direction.IN)
SPEED = Topic("speed", "geometry_msgs/msg/TwistStamped", SENSOR_QOS, Direction.IN)
POWER = Topic("power", "itt_msgs/msg/PowerStamped", SENSOR_QOS, Direction.IN)

SAMPLE_TOPICS: tuple[SampleTopic[Any], ...] = (
    SampleTopic(GPS_FIX, GpsFix, msg_to_gps_fix, gps_fix_to_msg),
    SampleTopic(SPEED, WheelSpeed, msg_to_wheel_speed, wheel_speed_to_msg),
    SampleTopic(POWER, PowerReading, msg_to_power_reading, power_reading_to_msg),
)
INPUT_TOPICS: tuple[Topic, ...] = tuple(e.topic for e in SAMPLE_TOPICS)
#: Every topic of the interface: the inputs, then the outputs.
TOPICS: tuple[Topic, ...] = (*INPUT_TOPICS, *OUTPUT_TOPICS)

_BY_TYPE: dict[type, SampleTopic[Any]] = {e.sample_type: e for e in SAMPLE_TOPICS}
_BY_KEY: dict[str, SampleTopic[Any]] = {e.topic.key: e for e in SAMPLE_TOPICS}


def topics_by_name(namespace: str = DEFAULT_NAMESPACE) -> dict[str, Topic]:
    """Map each fully qualified topic name in `namespace` to its `Topic`."""
    return {t.name(namespace): t for t in TOPICS}


def prepare_codecs(topics: tuple[Topic, ...] = TOPICS) -> None:
    """Do now, once, what the first message of each topic would otherwise do: generate
    its type's CDR code (rosbags compiles a type's (de)serializer on first use), its
    `ros2msg` schema text and its offered-QoS YAML (what a log's channel carries).

    For the interface's types that first use cost 0.7 s on a quiet machine and seconds
    under load. The pacing node paid it on its first advice, holding its output log's
    lock, and meanwhile its input callbacks waited on that lock: the best-effort
    inputs beyond the subscriptions' depth were lost (bench/RESULTS.md, 2026-12-03,
    helper R4). A node calls this before it says it is ready.
    """
    for topic in topics:
        typestore.get_msgdef(topic.msgtype)
        msgdef(topic.msgtype)
        offered_qos_yaml(topic.qos)


def is_sample(value: object) -> TypeGuard[Sample]:
    """Whether `value` is an input sample of a registered type."""
    return type(value) in _BY_TYPE


def sample_to_msg(sample: Sample) -> tuple[Topic, Any]:
    """The input topic of a core sample and its message.

    Raises:
        TypeError: not a sample of a registered type.
    """
    entry = _BY_TYPE.get(type(sample))
    if entry is None:
        raise TypeError(f"not a registered input sample: {type(sample).__name__}")
    return entry.topic, entry.to_msg(sample)


def to_core(topic: Topic, msg: Any) -> object:
    """The core value of a message on `topic`: the sample of an input topic, the core
    object of an output (`Advice`, list of `Diagnostic`), or the message itself for
    types the core has no twin of (`TargetPower`, `Path`)."""
    entry = _BY_KEY.get(topic.key)
    return entry.to_sample(msg) if entry is not None else output_to_core(msg)
