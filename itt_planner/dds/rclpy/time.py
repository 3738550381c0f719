"""`rclpy.time.Time`: a point in time of a clock, in integer nanoseconds."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from itt_planner.dds.rclpy.clock_type import ClockType
from itt_planner.dds.rclpy.duration import Duration


@dataclass(frozen=True, init=False)
class Time:
    """`Time(seconds=..., nanoseconds=..., clock_type=ClockType.ROS_TIME)`."""

    nanoseconds: int
    clock_type: ClockType

    def __init__(self, *, seconds: float = 0.0, nanoseconds: int = 0,
                 clock_type: ClockType = ClockType.SYSTEM_TIME) -> None:
        object.__setattr__(self, "nanoseconds", round(seconds * 1e9) + int(nanoseconds))
        object.__setattr__(self, "clock_type", clock_type)

    def seconds_nanoseconds(self) -> tuple[int, int]:
        """(sec, nanosec) as in `builtin_interfaces/Time`."""
        return divmod(self.nanoseconds, 1_000_000_000)

    def to_msg(self) -> Any:
        """`builtin_interfaces/Time`."""
        from itt_msgs_py import typestore

        sec, nsec = self.seconds_nanoseconds()
        return typestore.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)

    @classmethod
    def from_msg(cls, msg: Any, clock_type: ClockType = ClockType.ROS_TIME) -> Time:
        """Time of a `builtin_interfaces/Time`."""
        return cls(nanoseconds=msg.sec * 1_000_000_000 + msg.nanosec, clock_type=clock_type)

    def __add__(self, other: Duration) -> Time:
        return Time(nanoseconds=self.nanoseconds + other.nanoseconds,
                    clock_type=self.clock_type)

    def __sub__(self, other: Time | Duration) -> Any:
        if isinstance(other, Time):
            return Duration(nanoseconds=self.nanoseconds - other.nanoseconds)
        return Time(nanoseconds=self.nanoseconds - other.nanoseconds, clock_type=self.clock_type)

    def __lt__(self, other: Time) -> bool:
        return self.nanoseconds < other.nanoseconds

    def __le__(self, other: Time) -> bool:
        return self.nanoseconds <= other.nanoseconds
