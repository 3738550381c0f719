# Copyright 2026 itt-planner team
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""The pacing node: ROS 2 topics in and out of an `itt_planner.session.ride_session.RideSession`.

Only ROS conversion lives here. One subscription per entry of the sample registry
(`itt_msgs_py.registry`: `gps/fix`, `speed`, `power`) takes CDR bytes, queued up to
`INPUT_DEPTH` deep, and decodes them with the entry's converter (so a malformed payload
is counted, not fatal);
a timer in its own mutually exclusive callback group runs the session's tick, so a long
solve never blocks the inputs; advice goes out as `target_power`, `target_line`
(nav_msgs/Path, frame `map`), `advice` and `/diagnostics`, serialized by `itt_msgs_py`
to the bytes rosidl's classes would give. The clock is ROS time under `use_sim_time`
(`/clock` from `itt-planner play --clock` or `ros2 bag play --clock`), else the newest
input stamp: never the wall clock.
"""

from __future__ import annotations

import signal
import threading
import time
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import try_shutdown

from itt_msgs_py import deserialize, registry, serialize, topics
from itt_msgs_py.convert import (
    advice_to_msg,
    diagnostics_to_msg,
    target_line_msg,
    target_power_msg,
)
from itt_planner.session.config import SessionConfig
from itt_planner.session.ride_session import RideSession
from itt_planner_ros.ros_types import message_class, qos_profile
from itt_planner_ros.signals import handle_signals

NODE_NAME = 'itt_pacing'
#: Parameters of the node itself; the session's come from `SessionConfig`.
NODE_PARAMS = {'tick_period_s': 0.1, 'rerun_sink': '', 'output_log': '',
               'state_file': '', 'state_period_s': 2.0}
#: History depth of the input subscriptions: what may queue while the node's callbacks
#: are held up (a tick, a loaded machine). The sensor profile's 5 held 0.6 s of a rate-2
#: replay's speed and power, and a node held up longer at the start of a ride lost them
#: (bench/RESULTS.md, 2026-12-03, helper R4); 100 hold a second of 100 Hz inputs. The
#: depth is the reader's own: publishers of any depth still match.
INPUT_DEPTH = 100
#: A clock jump longer than this (a player restarted further on) is not ticked through.
MAX_CATCH_UP_S = 5.0
#: After SIGINT/SIGTERM, how long the callbacks under way may take to end (`run`). With
#: the re-solve worker killed, the longest is a tick's horizon solve: up to 0.93 s wall
#: at load ~3.5 on 2 cores (120 iterations, the deterministic cap, 2026-12-03).
STOP_GRACE_S = 10.0
#: How soon the executor's thread sees a stop (`_spin`).
SPIN_POLL_S = 0.1


class _Calls:
    """The node's callbacks under way, so a stop can wait for them; none starts after."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self.running = 0
        self._closed = False

    def begin(self) -> bool:
        """Count a callback in; False (not counted: return at once) once closed."""
        with self._cond:
            if self._closed:
                return False
            self.running += 1
            return True

    def end(self) -> None:
        with self._cond:
            self.running -= 1
            self._cond.notify_all()

    def close(self, timeout_s: float) -> bool:
        """Let no callback start; wait for those running. Returns whether all ended."""
        with self._cond:
            self._closed = True
            return self._cond.wait_for(lambda: self.running == 0, timeout_s)


class PacingNode(Node):
    """Declare the parameters, open the session, create the topics and the timer."""

    def __init__(self, *, namespace: str = topics.DEFAULT_NAMESPACE,
                 parameter_overrides: list[Any] | None = None) -> None:
        super().__init__(NODE_NAME, namespace=namespace,
                         parameter_overrides=parameter_overrides or [])
        session_fields = [f for f in fields(SessionConfig) if f.name != 'namespace']
        value = {name: self.declare_parameter(name, default).value
                 for name, default in [*((f.name, f.default) for f in session_fields),
                                       *NODE_PARAMS.items()]}
        config = SessionConfig(namespace=self.get_namespace(),
                               **{f.name: value[f.name] for f in session_fields})
        self.params = value
        sinks = (value['rerun_sink'],) if value['rerun_sink'] else ()
        self.session = RideSession.open(config, output_log=value['output_log'] or None,
                                        rerun_sinks=sinks, publish=self._publish,
                                        max_catch_up_s=MAX_CATCH_UP_S)
        self._state_path = Path(value['state_file']) if value['state_file'] else None
        #: The callbacks under way (`run` waits for them before it closes the session).
        self.calls = _Calls()
        self._last_save = time.monotonic()
        try:
            self._resume()
            # Now, not on the first advice: that tick holds the output log's lock, which
            # the input callbacks wait for (`registry.prepare_codecs`).
            registry.prepare_codecs()
            for entry in registry.SAMPLE_TOPICS:
                topic = entry.topic
                self.create_subscription(
                    message_class(topic.msgtype), topic.key, self._on_input(entry),
                    qos_profile(replace(topic.qos, depth=INPUT_DEPTH)), raw=True)
            self._pub = {t.key: self.create_publisher(message_class(t.msgtype), t.key,
                                                      qos_profile(t.qos))
                         for t in topics.OUTPUT_TOPICS}
            # The replan may take longer than a tick: its own group keeps inputs flowing.
            self.create_timer(value['tick_period_s'], self._tick,
                              callback_group=MutuallyExclusiveCallbackGroup())
        except BaseException:
            self.session.close()  # the output log is finished even when start-up fails
            raise
        self.logger().info(
            f'ready on {self.get_namespace()}: course {config.course}, rider {config.rider},'
            f' plan {self.session.plan.solver_status}, replan every {config.replan_period_s} s')
        for warning in self.session.setup_warnings():
            self.logger().warning(warning)

    def logger(self) -> Any:
        """The node's rclpy logger (rclpy's untyped calls are allowed, pyproject, but
        not through a subclass)."""
        return self.get_logger()  # type: ignore[no-untyped-call]

    def _on_input(self, entry: registry.SampleTopic[Any]) -> Any:
        topic = entry.topic

        def callback(data: bytes) -> None:
            if not self.calls.begin():
                return
            try:
                try:
                    sample = entry.to_sample(deserialize(data, topic.msgtype))
                except Exception as err:  # noqa: BLE001  (a corrupt payload raises many types)
                    self.session.on_malformed(topic.key, f'{type(err).__name__}: {err}')
                    return
                self.session.on_sample(sample)  # the engine counts samples it rejects
            finally:
                self.calls.end()
        return callback

    def _now_s(self) -> float | None:
        if self.get_parameter('use_sim_time').value:
            ns = self.get_clock().now().nanoseconds
            return ns * 1e-9 if ns > 0 else None
        state = self.session.engine.state
        return None if state is None else state.stamp_s

    def _tick(self) -> None:
        if not self.calls.begin():
            return
        try:
            self._tick_counted()
        finally:
            self.calls.end()

    def _tick_counted(self) -> None:
        now = self._now_s()
        if now is not None:
            try:
                self.session.advance_to(now)
            except Exception as err:  # noqa: BLE001  (a live node outlives a broken tick)
                self.session.on_malformed('engine_exception', f'{type(err).__name__}: {err}')
        if time.monotonic() - self._last_save >= self.params['state_period_s']:
            self.save_state()

    def _publish(self, advice: Any, diagnostics: Any, stamp_s: float) -> None:
        if advice is not None:
            self._pub['advice'].publish(serialize(advice_to_msg(advice)))
            self._pub['target_power'].publish(serialize(target_power_msg(advice)))
            self._pub['target_line'].publish(serialize(target_line_msg(advice)))
        if diagnostics is not None:
            self._pub['/diagnostics'].publish(
                serialize(diagnostics_to_msg(diagnostics, stamp_s)))

    def _resume(self) -> None:
        if self._state_path is None:
            return
        try:
            w_prime = self.session.restore_state(self._state_path)
        except ValueError as err:
            self.logger().warning(f'{err}: starting fresh')
            return
        if w_prime is not None:
            self.logger().info(f"resumed from {self._state_path}: W' {w_prime:.0f} J")

    def save_state(self) -> None:
        """Persist the engine's W' state now (no-op without `state_file`)."""
        self._last_save = time.monotonic()
        if self._state_path is None:
            return
        try:
            self.session.save_state(self._state_path)
        except OSError as err:
            self.logger().error(f'cannot save state to {self._state_path}: {err}',
                                    throttle_duration_sec=30.0)


def run(args: list[str] | None = None, *, namespace: str = topics.DEFAULT_NAMESPACE,
        parameter_overrides: list[Any] | None = None) -> dict[str, Any]:
    """Spin the node until SIGINT/SIGTERM; save its state, finish its outputs.

    The signals are this function's, not rclpy's (`rclpy.init` without its handlers).
    rclpy's handler wakes the executor first and shuts the context down after, from
    another thread: an executor that woke before the shutdown waited again, on a context
    that nothing would wake any more (with `use_sim_time` and the player gone, its timer
    never fires: SIGTERM left the node spinning for good, in 1 of 8 pipeline tests and 1
    of 30 SIGTERMs after a short play, load 4-13 on 2 cores, 2026-12-03), or built its
    next wait set as the context went away (RCLError traceback, no result: 3 of 16
    SIGTERMs mid-ride; 0 of 30 and 0 of 13 here). Here a signal only sets an
    event; the executor spins on a thread of its own, sees it and is joined, then the
    re-solve worker is killed and the callbacks under way are waited for
    (`STOP_GRACE_S`), and only then are the node and the context shut down.

    Raises:
        IttError: the course, rider or plan cannot be had.
    """
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    previous = handle_signals(stop)
    node = None
    ready = False
    try:
        node = PacingNode(namespace=namespace, parameter_overrides=parameter_overrides)
        # A signal during start-up (the plan solve can take a minute) is seen here: a
        # stop before the node was ready, not a failure.
        ready = not stop.is_set()
        if ready:
            _spin_until(node, stop)
    except KeyboardInterrupt:  # SIGINT before the handlers were installed
        pass
    finally:
        result = {} if node is None or not ready else {
            'namespace': node.get_namespace(), **node.session.counts(),
            'malformed': dict(node.session.malformed)}
        if node is not None:
            node.save_state()
            node.session.close()
            node.destroy_node()  # type: ignore[no-untyped-call]
        try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return result


def _spin_until(node: PacingNode, stop: threading.Event) -> None:
    """Run the node's callbacks on an executor thread until `stop` is set, then stop
    them in order (`run`). The main thread waits on the event, so a signal's handler runs
    at once (a thread blocked in rcl_wait would run it only when the wait returns)."""
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    errors: list[BaseException] = []
    spinning = threading.Thread(target=_spin, args=(executor, stop, errors), name='executor')
    spinning.start()
    try:
        stop.wait()
    finally:
        stop.set()
        spinning.join()
        # Kill a running course re-solve first: a tick waiting for it then returns.
        node.session.engine.close()
        if not node.calls.close(STOP_GRACE_S):
            node.logger().error(f'{node.calls.running} callback(s) still running '
                              f'{STOP_GRACE_S:.0f} s after the stop; stopping anyway')
        executor.shutdown(timeout_sec=0)
    if errors:
        raise errors[0]


def _spin(executor: MultiThreadedExecutor, stop: threading.Event,
          errors: list[BaseException]) -> None:
    """Dispatch callbacks until `stop` (seen within `SPIN_POLL_S`: `Executor.wake`
    does not end a `spin_once` that has no callback to run); a callback's error (raised
    here by the executor) stops the node and is raised again by `_spin_until`."""
    try:
        while not stop.is_set():
            executor.spin_once(timeout_sec=SPIN_POLL_S)
    except ExternalShutdownException:
        pass
    except BaseException as err:  # noqa: BLE001  (handed to the main thread)
        errors.append(err)
    finally:
        stop.set()


def main(args: list[str] | None = None) -> None:
    """Console script (`ros2 run itt_planner_ros pacing_node`)."""
    run(args)


if __name__ == '__main__':
    main()
