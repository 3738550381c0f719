"""`rclpy.callback_groups`: which callbacks may run at the same time."""

from __future__ import annotations

import threading


class CallbackGroup:
    """Base: tracks the callbacks of the group that are running now."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._running = 0

    def can_execute(self) -> bool:
        """Whether one more callback of this group may start now."""
        raise NotImplementedError

    def beginning_execution(self) -> bool:
        """Claim a slot; False if the group does not allow another callback now."""
        with self._lock:
            if not self._allowed(self._running):
                return False
            self._running += 1
            return True

    def ending_execution(self) -> None:
        """Release the slot taken by `beginning_execution`."""
        with self._lock:
            self._running -= 1

    def _allowed(self, running: int) -> bool:
        raise NotImplementedError


class MutuallyExclusiveCallbackGroup(CallbackGroup):
    """One callback of the group at a time (a long solve gets a group of its own)."""

    def can_execute(self) -> bool:
        """True when none of the group's callbacks is running."""
        with self._lock:
            return self._running == 0

    def _allowed(self, running: int) -> bool:
        return running == 0


class ReentrantCallbackGroup(CallbackGroup):
    """Any number of the group's callbacks at once."""

    def can_execute(self) -> bool:
        """Always True."""
        return True

    def _allowed(self, running: int) -> bool:
        return True
