"""`rclpy.clock_type.ClockType`."""

from __future__ import annotations

from enum import IntEnum


class ClockType(IntEnum):
    """As rclpy (values of rcl_clock_type_t)."""

    UNINITIALIZED = 0
    ROS_TIME = 1
    SYSTEM_TIME = 2
    STEADY_TIME = 3
