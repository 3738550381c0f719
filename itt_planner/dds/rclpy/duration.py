"""`rclpy.duration.Duration`: a signed span of time in integer nanoseconds."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, order=True, init=False)
class Duration:
    """`Duration(seconds=1.5)` or `Duration(nanoseconds=...)` (both add up, as rclpy)."""

    nanoseconds: int

    def __init__(self, *, seconds: float = 0.0, nanoseconds: int = 0) -> None:
        object.__setattr__(self, "nanoseconds", round(seconds * 1e9) + int(nanoseconds))

    def to_msg(self) -> object:
        """`builtin_interfaces/Duration`."""
        from itt_msgs_py import typestore

        sec, nsec = divmod(self.nanoseconds, 1_000_000_000)
        return typestore.types["builtin_interfaces/msg/Duration"](sec=sec, nanosec=nsec)
