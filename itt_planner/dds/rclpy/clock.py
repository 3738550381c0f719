"""`rclpy.clock`: the system clock and the ROS clock, which follows /clock under sim time.

With `use_sim_time` a node's ROS clock reads the last `/clock` message (zero before the
first one), as ROS 2's TimeSource does; otherwise it reads the system clock.
"""

from __future__ import annotations

import threading
import time as _time
from collections.abc import Callable

from itt_planner.dds.rclpy.clock_type import ClockType
from itt_planner.dds.rclpy.time import Time


class Clock:
    """A clock of `clock_type`; `now()` reads it."""

    def __init__(self, *, clock_type: ClockType = ClockType.SYSTEM_TIME) -> None:
        self.clock_type = clock_type

    def now(self) -> Time:
        """The current time of this clock."""
        ns = (_time.monotonic_ns() if self.clock_type is ClockType.STEADY_TIME
              else _time.time_ns())
        return Time(nanoseconds=ns, clock_type=self.clock_type)


class ROSClock(Clock):
    """The ROS clock: system time, or the simulated time of `/clock` when active."""

    def __init__(self) -> None:
        super().__init__(clock_type=ClockType.ROS_TIME)
        self._lock = threading.Lock()
        self._sim_active = False
        self._sim_ns = 0
        self._listeners: list[Callable[[], None]] = []

    @property
    def ros_time_is_active(self) -> bool:
        """True when the clock follows `/clock`."""
        return self._sim_active

    def _set_ros_time_is_active(self, active: bool) -> None:
        self._sim_active = active

    def set_ros_time_override(self, time: Time) -> None:
        """Set the simulated time (from a `/clock` message); wakes timers on it."""
        with self._lock:
            self._sim_ns = time.nanoseconds
            listeners = list(self._listeners)
        for listener in listeners:
            listener()

    def add_time_listener(self, listener: Callable[[], None]) -> None:
        """Call `listener` after each simulated-time update (executors re-check timers)."""
        with self._lock:
            self._listeners.append(listener)

    def now(self) -> Time:
        """Simulated time when active, else system time."""
        if self._sim_active:
            return Time(nanoseconds=self._sim_ns, clock_type=self.clock_type)
        return Time(nanoseconds=_time.time_ns(), clock_type=self.clock_type)
