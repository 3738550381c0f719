"""Topic names, message types and QoS of the itt-planner ROS 2 interface: the outputs here.

What flows where (architecture.md, "Topics"): the input topics are the sample registry's
entries (`registry`, with their sample types and converters), the outputs are defined
here, and `registry.TOPICS` lists both. Names are relative to a
namespace (default `/itt`, so `gps/fix` is `/itt/gps/fix`); `/diagnostics` is absolute,
as ROS tools expect it there. QoS is plain data here; the DDS layer and the rclpy node
map it onto their own profile types.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

DEFAULT_NAMESPACE = "/itt"


class Reliability(Enum):
    """DDS reliability kind."""

    BEST_EFFORT = "best_effort"
    RELIABLE = "reliable"


class History(Enum):
    """DDS history kind."""

    KEEP_LAST = "keep_last"
    KEEP_ALL = "keep_all"


class Durability(Enum):
    """DDS durability kind."""

    VOLATILE = "volatile"
    TRANSIENT_LOCAL = "transient_local"


class Direction(Enum):
    """Whether the pacing node subscribes to (IN) or publishes (OUT) a topic."""

    IN = "in"
    OUT = "out"


@dataclass(frozen=True)
class QoS:
    """A ROS 2 QoS profile as plain values."""

    reliability: Reliability
    depth: int
    history: History = History.KEEP_LAST
    durability: Durability = Durability.VOLATILE


#: ROS `qos_profile_sensor_data`: a late sample is worth less than the next one.
SENSOR_QOS = QoS(Reliability.BEST_EFFORT, depth=5)
#: Outputs the team car must not miss (ROS default profile: reliable, keep-last 10).
RELIABLE_QOS = QoS(Reliability.RELIABLE, depth=10)


@dataclass(frozen=True)
class Topic:
    """One topic of the interface.

    Attributes:
        key: name relative to the namespace (`gps/fix`), or absolute (`/diagnostics`).
        msgtype: ROS 2 type name, `pkg/msg/Name`.
    """

    key: str
    msgtype: str
    qos: QoS
    direction: Direction

    def name(self, namespace: str = DEFAULT_NAMESPACE) -> str:
        """Fully qualified topic name in `namespace`."""
        if self.key.startswith("/"):
            return self.key
        return f"{normalize_namespace(namespace)}/{self.key}"


TARGET_POWER = Topic("target_power", "itt_msgs/msg/TargetPower", RELIABLE_QOS, Direction.OUT)
TARGET_LINE = Topic("target_line", "nav_msgs/msg/Path", RELIABLE_QOS, Direction.OUT)
ADVICE = Topic("advice", "itt_msgs/msg/Advice", RELIABLE_QOS, Direction.OUT)
DIAGNOSTICS = Topic("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", RELIABLE_QOS,
                    Direction.OUT)

#: What the pacing node publishes (its inputs are the sample registry's, `registry`).
OUTPUT_TOPICS: tuple[Topic, ...] = (TARGET_POWER, TARGET_LINE, ADVICE, DIAGNOSTICS)


def normalize_namespace(namespace: str) -> str:
    """`itt`, `/itt/` and `/itt` all become `/itt`; the root namespace is `""`.

    Raises:
        ValueError: the namespace holds characters ROS names do not allow.
    """
    parts = [p for p in namespace.strip().split("/") if p]
    for part in parts:
        if not (part[0].isalpha() or part[0] == "_") or not all(
            c.isalnum() or c == "_" for c in part
        ):
            raise ValueError(f"invalid ROS namespace {namespace!r}: bad token {part!r}")
    return "".join(f"/{p}" for p in parts)

