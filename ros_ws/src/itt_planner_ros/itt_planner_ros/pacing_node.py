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
(`itt_msgs_py.registry`: `gps/fix`, `speed`, `power`) takes CDR bytes and decodes them
with the entry's converter (so a malformed payload is counted, not fatal);
a timer in its own mutually exclusive callback group runs the session's tick, so a long
solve never blocks the inputs; advice goes out as `target_power`, `target_line`
(nav_msgs/Path, frame `map`), `advice` and `/diagnostics`, serialized by `itt_msgs_py`
to the bytes rosidl's classes would give. The clock is ROS time under `use_sim_time`
(`/clock` from `itt-planner play --clock` or `ros2 bag play --clock`), else the newest
input stamp: never the wall clock.
"""

from __future__ import annotations

import time
from dataclasses import fields
from pathlib import Path
from typing import Any

import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.utilities import ok as rclpy_ok
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

NODE_NAME = 'itt_pacing'
#: Parameters of the node itself; the session's come from `SessionConfig`.
NODE_PARAMS = {'tick_period_s': 0.1, 'rerun_sink': '', 'output_log': '',
               'state_file': '', 'state_period_s': 2.0}
#: A clock jump longer than this (a player restarted further on) is not ticked through.
MAX_CATCH_UP_S = 5.0


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
        self._last_save = time.monotonic()
        try:
            self._resume()
            for entry in registry.SAMPLE_TOPICS:
                topic = entry.topic
                self.create_subscription(message_class(topic.msgtype), topic.key,
                                         self._on_input(entry), qos_profile(topic.qos),
                                         raw=True)
            self._pub = {t.key: self.create_publisher(message_class(t.msgtype), t.key,
                                                      qos_profile(t.qos))
                         for t in topics.OUTPUT_TOPICS}
            # The replan may take longer than a tick: its own group keeps inputs flowing.
            self.create_timer(value['tick_period_s'], self._tick,
                              callback_group=MutuallyExclusiveCallbackGroup())
        except BaseException:
            self.session.close()  # the output log is finished even when start-up fails
            raise
        self._log().info(
            f'ready on {self.get_namespace()}: course {config.course}, rider {config.rider},'
            f' plan {self.session.plan.solver_status}, replan every {config.replan_period_s} s')

    def _log(self) -> Any:
        # rclpy's untyped calls are allowed (pyproject) but not through a subclass.
        return self.get_logger()  # type: ignore[no-untyped-call]

    def _on_input(self, entry: registry.SampleTopic[Any]) -> Any:
        topic = entry.topic

        def callback(data: bytes) -> None:
            try:
                sample = entry.to_sample(deserialize(data, topic.msgtype))
            except Exception as err:  # noqa: BLE001  (a corrupt payload raises many types)
                self.session.on_malformed(topic.key, f'{type(err).__name__}: {err}')
                return
            self.session.on_sample(sample)  # the engine counts samples it rejects
        return callback

    def _now_s(self) -> float | None:
        if self.get_parameter('use_sim_time').value:
            ns = self.get_clock().now().nanoseconds
            return ns * 1e-9 if ns > 0 else None
        state = self.session.engine.state
        return None if state is None else state.stamp_s

    def _tick(self) -> None:
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
            self._log().warning(f'{err}: starting fresh')
            return
        if w_prime is not None:
            self._log().info(f"resumed from {self._state_path}: W' {w_prime:.0f} J")

    def save_state(self) -> None:
        """Persist the engine's W' state now (no-op without `state_file`)."""
        self._last_save = time.monotonic()
        if self._state_path is None:
            return
        try:
            self.session.save_state(self._state_path)
        except OSError as err:
            self._log().error(f'cannot save state to {self._state_path}: {err}',
                                    throttle_duration_sec=30.0)


def run(args: list[str] | None = None, *, namespace: str = topics.DEFAULT_NAMESPACE,
        parameter_overrides: list[Any] | None = None) -> dict[str, Any]:
    """Spin the node until SIGINT/SIGTERM; save its state, finish its outputs.

    Raises:
        IttError: the course, rider or plan cannot be had.
    """
    rclpy.init(args=args)
    node = None
    try:
        try:
            node = PacingNode(namespace=namespace, parameter_overrides=parameter_overrides)
        except Exception:
            if rclpy_ok():
                raise
            # SIGINT/SIGTERM during start-up (the plan solve can take a minute) shut the
            # context down under the constructor: that is a stop, not a failure.
            return {}
        executor = MultiThreadedExecutor(num_threads=4)
        executor.add_node(node)
        try:
            executor.spin()
        finally:
            # Kill a running course re-solve first: a tick waiting for it then returns,
            # and the executor's shutdown does not wait minutes for that solve.
            node.session.engine.close()
            executor.shutdown()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        result = {} if node is None else {'namespace': node.get_namespace(),
                                           **node.session.counts(),
                                           'malformed': dict(node.session.malformed)}
        if node is not None:
            node.save_state()
            node.session.close()
            node.destroy_node()  # type: ignore[no-untyped-call]
        try_shutdown()
    return result


def main(args: list[str] | None = None) -> None:
    """Console script (`ros2 run itt_planner_ros pacing_node`)."""
    run(args)


if __name__ == '__main__':
    main()
