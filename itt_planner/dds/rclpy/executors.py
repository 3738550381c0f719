"""`rclpy.executors`: run the callbacks of nodes' timers and subscriptions.

One loop finds what is ready (a subscription with data, a due timer) and whose callback
group allows it to start, then runs it inline (`SingleThreadedExecutor`) or on a thread
pool (`MultiThreadedExecutor`, so a long solve in its own group never blocks the input
callbacks). DDS listeners, clock updates and finished callbacks wake the loop.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

from itt_planner.dds.context import Context, default_context
from itt_planner.dds.rclpy.node import Node, Subscription, Timer

#: Longest sleep between checks: a safety net, wake-ups normally come earlier.
MAX_WAIT_S = 0.5


class ExternalShutdownException(Exception):
    """The context was shut down (Ctrl-C, SIGTERM, `rclpy.shutdown()`) while spinning."""


Entity = Subscription | Timer


class Executor:
    """Base executor: the wait/dispatch loop; subclasses decide where callbacks run."""

    def __init__(self, *, context: Context | None = None) -> None:
        self.context = context or default_context
        self._nodes: list[Node] = []
        self._cv = threading.Condition()
        self._woken = False
        self._in_flight: set[int] = set()
        self._errors: list[BaseException] = []
        self._is_shutdown = False
        self.context.on_shutdown(self.wake)

    def wake(self) -> None:
        """Make the loop look for ready work now."""
        with self._cv:
            self._woken = True
            self._cv.notify_all()

    def add_node(self, node: Node) -> bool:
        """Spin `node` too."""
        if node in self._nodes:
            return False
        self._nodes.append(node)
        node._add_waker(self.wake)
        self.wake()
        return True

    def remove_node(self, node: Node) -> None:
        """Stop spinning `node`."""
        if node in self._nodes:
            self._nodes.remove(node)
            node._remove_waker(self.wake)

    def get_nodes(self) -> list[Node]:
        """The nodes being spun."""
        return list(self._nodes)

    def _ready(self) -> list[Entity]:
        ready: list[Entity] = []
        for node in self._nodes:
            for entity in (*node.subscriptions, *node.timers):
                if id(entity) not in self._in_flight and entity.is_ready():
                    ready.append(entity)
        return ready

    def _timeout_s(self) -> float:
        timeout = MAX_WAIT_S
        for node in self._nodes:
            for timer in node.timers:
                clock = timer.clock
                if getattr(clock, "ros_time_is_active", False):
                    continue  # sim time: the clock listener wakes us
                remaining = timer.time_until_next_call()
                if remaining is not None:
                    timeout = min(timeout, max(remaining, 0) * 1e-9)
        return timeout

    def _claim(self, entity: Entity) -> bool:
        with self._cv:
            if id(entity) in self._in_flight:
                return False
            if not entity.callback_group.beginning_execution():
                return False
            self._in_flight.add(id(entity))
            return True

    def _execute(self, entity: Entity) -> None:
        try:
            entity.execute()
        except BaseException as err:  # noqa: BLE001  (re-raised from spin(), as rclpy does)
            with self._cv:
                self._errors.append(err)
        finally:
            entity.callback_group.ending_execution()
            with self._cv:
                self._in_flight.discard(id(entity))
            self.wake()

    def _dispatch(self, entity: Entity) -> None:
        raise NotImplementedError

    def _raise_errors(self) -> None:
        with self._cv:
            errors, self._errors = self._errors, []
        if errors:
            raise errors[0]

    def _step(self, timeout_s: float | None) -> bool:
        """Dispatch what is ready, else wait up to `timeout_s`; True if anything ran."""
        self._raise_errors()
        if not self.context.ok():
            raise ExternalShutdownException
        dispatched = False
        for entity in self._ready():
            if self._claim(entity):
                self._dispatch(entity)
                dispatched = True
        if dispatched:
            return True
        wait = self._timeout_s() if timeout_s is None else min(timeout_s, self._timeout_s())
        with self._cv:
            if not self._woken:
                self._cv.wait(wait)
            self._woken = False
        return False

    def spin_once(self, timeout_sec: float | None = None) -> None:
        """Run what is ready, or wait for it up to `timeout_sec`.

        Raises:
            ExternalShutdownException: the context was shut down.
        """
        if not self._step(timeout_sec):
            self._step(0.0)

    def spin(self) -> None:
        """Run callbacks until the context or this executor shuts down.

        Raises:
            ExternalShutdownException: the context was shut down from outside.
        """
        while not self._is_shutdown:
            self._step(None)
        self._raise_errors()

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        """Stop spinning and let running callbacks finish."""
        self._is_shutdown = True
        self.wake()
        return True


class SingleThreadedExecutor(Executor):
    """Runs every callback on the spinning thread."""

    def _dispatch(self, entity: Entity) -> None:
        self._execute(entity)


class MultiThreadedExecutor(Executor):
    """Runs callbacks on `num_threads` threads, within their groups' rules."""

    def __init__(self, num_threads: int | None = None, *, context: Context | None = None,
                 **_unused: Any) -> None:
        super().__init__(context=context)
        self._pool = ThreadPoolExecutor(max_workers=num_threads or os.cpu_count() or 2,
                                        thread_name_prefix="executor")
        self._futures: set[Future[None]] = set()

    def _dispatch(self, entity: Entity) -> None:
        future = self._pool.submit(self._execute, entity)
        self._futures.add(future)
        future.add_done_callback(self._futures.discard)

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        """Stop spinning; wait for the running callbacks."""
        super().shutdown(timeout_sec)
        self._pool.shutdown(wait=True, cancel_futures=True)
        return True
