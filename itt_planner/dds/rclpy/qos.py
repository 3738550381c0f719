"""`rclpy.qos` subset: QoS profiles and the policies the pacing interface uses."""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from itt_msgs_py import topics


class ReliabilityPolicy(IntEnum):
    """As rclpy (values of rmw_qos_reliability_policy_t)."""

    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2


class HistoryPolicy(IntEnum):
    """As rclpy (values of rmw_qos_history_policy_t)."""

    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


class DurabilityPolicy(IntEnum):
    """As rclpy (values of rmw_qos_durability_policy_t)."""

    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


@dataclass(frozen=True)
class QoSProfile:
    """A QoS profile; rclpy's defaults (reliable, keep-last, volatile)."""

    depth: int = 10
    reliability: ReliabilityPolicy = ReliabilityPolicy.RELIABLE
    history: HistoryPolicy = HistoryPolicy.KEEP_LAST
    durability: DurabilityPolicy = DurabilityPolicy.VOLATILE

    def plain(self) -> topics.QoS:
        """The profile as `itt_msgs_py` QoS data (system default = ROS 2's default)."""
        return topics.QoS(
            reliability=(topics.Reliability.BEST_EFFORT
                         if self.reliability is ReliabilityPolicy.BEST_EFFORT
                         else topics.Reliability.RELIABLE),
            depth=self.depth,
            history=(topics.History.KEEP_ALL if self.history is HistoryPolicy.KEEP_ALL
                     else topics.History.KEEP_LAST),
            durability=(topics.Durability.TRANSIENT_LOCAL
                        if self.durability is DurabilityPolicy.TRANSIENT_LOCAL
                        else topics.Durability.VOLATILE),
        )


def as_profile(qos: QoSProfile | int) -> QoSProfile:
    """rclpy accepts a bare history depth wherever a profile goes."""
    return QoSProfile(depth=qos) if isinstance(qos, int) else qos


#: `rclpy.qos.qos_profile_sensor_data`.
qos_profile_sensor_data = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
#: The default profile of publishers and subscriptions.
qos_profile_system_default = QoSProfile()
#: `rclcpp::ClockQoS()`: what `ros2 bag play --clock` publishes /clock with.
qos_profile_clock = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
