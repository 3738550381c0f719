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

"""The pacing node: ROS 2 topics in and out of `itt_planner.engine.PacingEngine`.

A thin adapter. Subscriptions (sensor-data QoS) decode `gps/fix`, `speed` and `power`
into core samples and hand them to the engine; a timer in its own mutually exclusive
callback group, under a multi-threaded executor, calls `engine.update(now)` and
publishes `target_power`, `target_line` (nav_msgs/Path, frame `map`), `advice` and
`/diagnostics`, so a long solve never blocks the inputs.

`now` is the ROS clock under `use_sim_time` (fed by `/clock`, e.g. `ros2 bag play
--clock` or `itt-planner play --clock`); otherwise the stamp of the newest input the
engine accepted: the engine is clocked by message stamps, never by the wall clock.

Runtime: real `rclpy` when it imports, else the rclpy-compatible layer over Cyclone DDS
(`itt_planner.dds.rclpy`); `ITT_RUNTIME=rclpy|dds` forces one. Messages travel as CDR
bytes on both (`raw=True` subscriptions, `publish(bytes)`), encoded by `itt_msgs_py`,
so the node code is the same on both and the bytes are those `rosbags` writes.

The engine's W' state is saved to `state_file` every `state_period_s` and at exit, and
restored at start, so a restarted node resumes with the W' it had. A payload that does
not decode is counted (diagnostic `itt_planner/node`) and logged, never fatal.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
import importlib
import json
import math
import os
from pathlib import Path
import threading
import time
from types import ModuleType
from typing import Any

from itt_msgs_py import deserialize, serialize, topics, typestore
from itt_msgs_py.convert import (
    advice_to_msg,
    diagnostics_to_msg,
    msg_to_gps_fix,
    msg_to_power_reading,
    msg_to_wheel_speed,
    target_line_msg,
    target_power_msg,
)
from itt_planner.advice import Advice, Diagnostic, Level

RUNTIME_ENV = 'ITT_RUNTIME'
NODE_NAME = 'itt_pacing'


def select_runtime(choice: str | None = None) -> tuple[str, ModuleType]:
    """("rclpy", rclpy) or ("dds", itt_planner.dds.rclpy), per `choice` or `ITT_RUNTIME`.

    Raises:
        ValueError: a choice other than auto, rclpy, dds.
        ImportError: `rclpy` was forced and is not installed.
    """
    choice = choice or os.environ.get(RUNTIME_ENV, 'auto') or 'auto'
    if choice not in ('auto', 'rclpy', 'dds'):
        raise ValueError(f'{RUNTIME_ENV}={choice!r}: expected auto, rclpy or dds')
    if choice != 'dds':
        try:
            return 'rclpy', importlib.import_module('rclpy')
        except ImportError:
            if choice == 'rclpy':
                raise
    return 'dds', importlib.import_module('itt_planner.dds.rclpy')


RUNTIME, rclpy = select_runtime()
_node = importlib.import_module(f'{rclpy.__name__}.node')
_executors = importlib.import_module(f'{rclpy.__name__}.executors')
_groups = importlib.import_module(f'{rclpy.__name__}.callback_groups')
_qos = importlib.import_module(f'{rclpy.__name__}.qos')
Parameter = importlib.import_module(f'{rclpy.__name__}.parameter').Parameter
Node = _node.Node
ExternalShutdownException = _executors.ExternalShutdownException


def message_type(msgtype: str) -> Any:
    """Return the runtime's class of ROS type `pkg/msg/Name` (generated on rclpy)."""
    if RUNTIME == 'rclpy':
        from rosidl_runtime_py.utilities import get_message

        return get_message(msgtype)
    return typestore.types[msgtype]


def qos_profile(qos: topics.QoS) -> Any:
    """Return the runtime's QoSProfile of a topic's plain QoS."""
    return _qos.QoSProfile(
        depth=qos.depth,
        reliability=(_qos.ReliabilityPolicy.BEST_EFFORT
                     if qos.reliability is topics.Reliability.BEST_EFFORT
                     else _qos.ReliabilityPolicy.RELIABLE),
        history=(_qos.HistoryPolicy.KEEP_ALL if qos.history is topics.History.KEEP_ALL
                 else _qos.HistoryPolicy.KEEP_LAST),
        durability=(_qos.DurabilityPolicy.TRANSIENT_LOCAL
                    if qos.durability is topics.Durability.TRANSIENT_LOCAL
                    else _qos.DurabilityPolicy.VOLATILE),
    )


@dataclass(frozen=True)
class NodeParams:
    """The node's ROS parameters (defaults in `config/params.yaml` too).

    Attributes:
        course: course spec for `load_course` (demo name, GPS file, `.course.npz`).
        rider: rider preset name or YAML file.
        plan: a saved full-course plan (`Plan.save`); "" to take it from `plan_cache`.
        plan_cache: directory of cached full-course plans (solved there when missing).
        horizon_m: receding-horizon length.
        replan_period_s: stamp time between two advices.
        on_plan_band_j: W' deviation from the plan within which the advice is the plan
            itself (no replan); 0.0 replans every period (`EngineSettings`).
        course_replan_period_s: off the plan, the rest of the course is re-solved in
            the background at most this often and adopted once solved
            (`CourseReplanSettings`); 0.0 never.
        line_gate_m: the horizon plans from the advised line unless the GPS puts the
            rider further off it than this (`EngineSettings`); 0.0 from the GPS always.
        tick_period_s: period of the replan timer (node clock); the engine decides
            whether a replan is due.
        diagnostics_period_s: stamp time between two `/diagnostics` messages.
        rerun_sink: Rerun destination ("file:ride.rrd", "spawn", "connect[:URL]",
            "serve"), "" for none.
        output_log: MCAP ride log of inputs and outputs, "" for none.
        state_file: JSON file of the engine's W' state, "" for no persistence.
        state_period_s: wall time between two saves of `state_file`.
    """

    course: str = 'verona-like'
    rider: str = 'paper'
    plan: str = ''
    plan_cache: str = '.itt_cache'
    horizon_m: float = 1000.0
    replan_period_s: float = 1.0
    on_plan_band_j: float = 2000.0
    course_replan_period_s: float = 30.0
    line_gate_m: float = 5.0
    tick_period_s: float = 0.1
    diagnostics_period_s: float = 1.0
    rerun_sink: str = ''
    output_log: str = ''
    state_file: str = ''
    state_period_s: float = 2.0


def build_engine(params: NodeParams) -> Any:
    """Build the pacing engine of the node's course, rider and full-course plan.

    Raises:
        IttError: the course, rider or plan cannot be had.
    """
    from itt_planner.conditions import Conditions
    from itt_planner.course_loader import load_course
    from itt_planner.course_replan import CourseReplanSettings
    from itt_planner.engine import EngineSettings, PacingEngine
    from itt_planner.plan import Plan
    from itt_planner.rider import load_rider

    course = load_course(params.course)
    rider = load_rider(params.rider)
    conditions = Conditions()
    if params.plan:
        plan = Plan.load(params.plan)
    else:
        from itt_planner.ocp import OcpSettings
        from itt_planner.plan_cache import load_or_solve

        plan = load_or_solve(course, rider, conditions, OcpSettings(), '3d',
                             cache_dir=Path(params.plan_cache))
    settings = EngineSettings(
        replan_period_s=params.replan_period_s, horizon_m=params.horizon_m,
        on_plan_band_j=params.on_plan_band_j, line_gate_m=params.line_gate_m,
        course_replan=CourseReplanSettings(period_s=params.course_replan_period_s))
    return PacingEngine(course, rider, plan, conditions=conditions, settings=settings)


def save_state(path: Path, engine: Any, course: str) -> None:
    """Write the engine snapshot atomically (a kill mid-write leaves the old file)."""
    tmp = path.with_name(path.name + '.tmp')
    tmp.write_text(json.dumps({'course': course, 'engine': engine.snapshot()}),
                   encoding='utf-8')
    os.replace(tmp, path)


def load_state(path: Path, course: str) -> dict[str, Any] | None:
    """Return the engine snapshot saved for `course`, None if there is none.

    Raises:
        ValueError: the file exists but is not a snapshot of this course.
    """
    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text(encoding='utf-8'))
    except (OSError, json.JSONDecodeError) as err:
        raise ValueError(f'{path}: unreadable state file ({err})') from None
    if not isinstance(doc, dict) or doc.get('course') != course or 'engine' not in doc:
        raise ValueError(f'{path}: not a saved state of course {course!r}')
    return doc['engine']


class PacingNode(Node):
    """The pacing node (see the module docstring).

    Args:
        namespace: ROS namespace of the pacing topics (`/itt`).
        parameter_overrides: runtime `Parameter`s that win over YAML and defaults.
        engine: a prebuilt engine; built from the parameters when None.
        context: the runtime's context (None: the default one).
    """

    def __init__(self, *, namespace: str = topics.DEFAULT_NAMESPACE,
                 parameter_overrides: list[Any] | None = None, engine: Any = None,
                 context: Any = None) -> None:
        """Declare the parameters, build the engine, create the topics and the timer."""
        super().__init__(NODE_NAME, namespace=namespace, context=context,
                         parameter_overrides=parameter_overrides or [])
        self.params = self._declare_parameters()
        self.engine = engine if engine is not None else build_engine(self.params)
        self.malformed: Counter[str] = Counter()
        self.advice_count = 0
        self._io_lock = threading.Lock()  # the MCAP writer is not thread-safe
        self._last_diag_stamp: float | None = None
        self._last_save_wall = time.monotonic()
        self._state_path = Path(self.params.state_file) if self.params.state_file else None
        self._restore_state()
        self._log_writer = self._open_output_log()
        self._recorder = self._open_rerun()

        inputs = (
            (topics.GPS_FIX, msg_to_gps_fix, self.engine.on_gps),
            (topics.SPEED, msg_to_wheel_speed, self.engine.on_speed),
            (topics.POWER, msg_to_power_reading, self.engine.on_power),
        )
        for topic, convert, feed in inputs:
            self.create_subscription(
                message_type(topic.msgtype), topic.key,
                self._input_callback(topic, convert, feed), qos_profile(topic.qos), raw=True)
        self._pub = {
            t.key: self.create_publisher(message_type(t.msgtype), t.key, qos_profile(t.qos))
            for t in (topics.TARGET_POWER, topics.TARGET_LINE, topics.ADVICE,
                      topics.DIAGNOSTICS)
        }
        # The replan may take longer than a tick: its own group keeps inputs flowing.
        self.replan_timer = self.create_timer(
            self.params.tick_period_s, self._tick,
            callback_group=_groups.MutuallyExclusiveCallbackGroup())
        self.get_logger().info(
            f'ready on {self.get_namespace()} ({RUNTIME}): course {self.params.course}, '
            f'rider {self.params.rider}, replan every {self.params.replan_period_s} s')

    def _declare_parameters(self) -> NodeParams:
        defaults = NodeParams()
        values = {name: self.declare_parameter(name, getattr(defaults, name)).value
                  for name in NodeParams.__dataclass_fields__}
        return NodeParams(**values)

    # --- inputs ----------------------------------------------------------------------

    def _input_callback(self, topic: topics.Topic, convert: Any, feed: Any) -> Any:
        def callback(data: bytes) -> None:
            try:
                sample = convert(deserialize(data, topic.msgtype))
            except Exception as err:  # noqa: BLE001  (a corrupt payload raises many types)
                self.malformed[topic.key] += 1
                self.get_logger().warning(
                    f'malformed {topic.msgtype} on {topic.key} dropped '
                    f'({type(err).__name__}: {err}); {self.malformed[topic.key]} so far',
                    throttle_duration_sec=5.0)
                return
            feed(sample)  # the engine counts and logs samples it rejects; never raises
            if self._log_writer is not None:
                with self._io_lock:
                    self._log_writer.write_sample(sample)
            if self._recorder is not None:
                log = {'gps/fix': self._recorder.log_gps, 'speed': self._recorder.log_speed,
                       'power': self._recorder.log_power}[topic.key]
                log(sample)
        return callback

    # --- the replan ------------------------------------------------------------------

    def now_s(self) -> float | None:
        """Return the engine's clock: ROS time under use_sim_time, else the newest stamp."""
        if self.get_parameter('use_sim_time').value:
            ns = self.get_clock().now().nanoseconds
            return ns * 1e-9 if ns > 0 else None
        state = self.engine.state
        return None if state is None else state.stamp_s

    def _tick(self) -> None:
        now = self.now_s()
        if now is not None:
            try:
                advice = self.engine.update(now)
            except Exception as err:  # noqa: BLE001  (the engine should not raise; a live
                # node must outlive it if it does)
                self.malformed['engine_exception'] += 1
                self.get_logger().error(f'engine.update raised {type(err).__name__}: {err}',
                                        throttle_duration_sec=5.0)
                advice = None
            if advice is not None:
                self._publish_advice(advice)
            if self._last_diag_stamp is None or \
                    now - self._last_diag_stamp >= self.params.diagnostics_period_s or \
                    now < self._last_diag_stamp:
                self._publish_diagnostics(now)
        if self._state_path is not None and \
                time.monotonic() - self._last_save_wall >= self.params.state_period_s:
            self.save_state()

    def _publish_advice(self, advice: Advice) -> None:
        self.advice_count += 1
        self._pub['advice'].publish(serialize(advice_to_msg(advice)))
        self._pub['target_power'].publish(serialize(target_power_msg(advice)))
        self._pub['target_line'].publish(serialize(target_line_msg(advice)))
        if self._log_writer is not None:
            with self._io_lock:
                self._log_writer.write_advice(advice)
        if self._recorder is not None:
            self._recorder.log_advice(advice)

    def node_diagnostic(self, stamp_s: float) -> Diagnostic:
        """Return the node's own health: malformed payloads, advice published."""
        bad = sum(self.malformed.values())
        return Diagnostic(
            stamp_s, 'itt_planner/node', Level.WARN if bad else Level.OK,
            f'{bad} malformed payload(s) dropped' if bad else 'ok',
            {'runtime': RUNTIME, 'advice_published': str(self.advice_count),
             **{f'malformed/{k}': str(v) for k, v in sorted(self.malformed.items())}})

    def _publish_diagnostics(self, stamp_s: float) -> None:
        self._last_diag_stamp = stamp_s
        diags = [*self.engine.diagnostics(stamp_s), self.node_diagnostic(stamp_s)]
        self._pub['/diagnostics'].publish(serialize(diagnostics_to_msg(diags, stamp_s)))
        if self._log_writer is not None:
            with self._io_lock:
                self._log_writer.write_diagnostics(diags, stamp_s)
        if self._recorder is not None:
            self._recorder.log_diagnostics(diags)

    # --- persistence and outputs -----------------------------------------------------

    def _restore_state(self) -> None:
        if self._state_path is None:
            return
        try:
            snap = load_state(self._state_path, self.params.course)
        except ValueError as err:
            self.get_logger().warning(f'{err}: starting fresh')
            return
        if snap is None:
            return
        try:
            self.engine.restore(snap)
        except (KeyError, TypeError, ValueError) as err:
            self.get_logger().warning(f'{self._state_path}: cannot restore ({err}); fresh')
            return
        w_prime = snap.get('estimator', {}).get('w_prime_j', math.nan)
        self.get_logger().info(f"resumed from {self._state_path}: W' {w_prime:.0f} J")

    def save_state(self) -> None:
        """Persist the engine's W' state now (no-op without `state_file`)."""
        self._last_save_wall = time.monotonic()
        if self._state_path is None:
            return
        try:
            save_state(self._state_path, self.engine, self.params.course)
        except OSError as err:
            self.get_logger().error(f'cannot save state to {self._state_path}: {err}',
                                    throttle_duration_sec=30.0)

    def _open_output_log(self) -> Any:
        if not self.params.output_log:
            return None
        from itt_planner.ridelog import RideLogWriter, RideMetadata

        return RideLogWriter(self.params.output_log, namespace=self.get_namespace(),
                             metadata=RideMetadata(source='itt_pacing node',
                                                   rider=self.params.rider))

    def _open_rerun(self) -> Any:
        if not self.params.rerun_sink:
            return None
        from itt_planner.rerun_log import RideRecorder
        from itt_planner.rerun_sink import RerunSink, open_recording

        recorder = RideRecorder(open_recording(RerunSink.parse(self.params.rerun_sink)),
                                self.engine.course, self.engine.rider, self.engine.plan)
        recorder.log_course()
        return recorder

    def close(self) -> None:
        """Save the state, stop the engine's worker, finish the output log, flush Rerun
        (call before exit)."""
        self.save_state()
        self.engine.close()
        if self._log_writer is not None:
            with self._io_lock:
                self._log_writer.close()
        if self._recorder is not None:
            self._recorder.rec.flush(timeout_sec=10.0)


def run(args: list[str] | None = None, *, namespace: str | None = None,
        parameter_overrides: list[Any] | None = None) -> dict[str, Any]:
    """Run the node until Ctrl-C / SIGTERM; returns what it did (advice, malformed).

    Raises:
        IttError: the course, rider or plan cannot be had.
    """
    rclpy.init(args=args)
    node = None
    try:
        node = PacingNode(namespace=namespace or topics.DEFAULT_NAMESPACE,
                          parameter_overrides=parameter_overrides)
        executor = _executors.MultiThreadedExecutor(num_threads=4)
        executor.add_node(node)
        try:
            executor.spin()
        finally:
            executor.shutdown()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.close()
            node.destroy_node()
        rclpy.try_shutdown()
    if node is None:
        return {}
    return {'runtime': RUNTIME, 'namespace': node.get_namespace(),
            'advice_published': node.advice_count, 'malformed': dict(node.malformed)}


def main(args: list[str] | None = None) -> None:
    """Console script (`ros2 run itt_planner_ros pacing_node`)."""
    run(args)


if __name__ == '__main__':
    main()
