"""`rclpy.node.Node` on Cyclone DDS: publishers, subscriptions, timers, parameters, clock.

Topic names resolve as in ROS 2: relative names against the node's namespace, `~/x`
against the node's name. Messages are rosbags objects of the itt typestore; a
publisher also takes pre-serialised CDR bytes and a subscription created with
`raw=True` hands its callback the bytes, as rclpy does.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import yaml

from itt_msgs_py import serialize, typestore
from itt_msgs_py.topics import normalize_namespace
from itt_planner.dds.context import Context, default_context
from itt_planner.dds.endpoints import RawReader, RawWriter
from itt_planner.dds.rclpy.callback_groups import CallbackGroup, MutuallyExclusiveCallbackGroup
from itt_planner.dds.rclpy.clock import Clock, ROSClock
from itt_planner.dds.rclpy.logging import RcutilsLogger, get_logger
from itt_planner.dds.rclpy.parameter import Parameter
from itt_planner.dds.rclpy.qos import QoSProfile, as_profile, qos_profile_clock
from itt_planner.dds.rclpy.time import Time

CLOCK_TOPIC = "/clock"


class ParameterNotDeclaredException(Exception):
    """Reading a parameter that was never declared (as rclpy)."""


class ParameterAlreadyDeclaredException(Exception):
    """Declaring a parameter twice (as rclpy)."""


def _msgtype(msg_type: Any) -> str:
    name = getattr(msg_type, "__msgtype__", None)
    if name is None or name not in typestore.types:
        raise TypeError(f"{msg_type!r} is not a message type of the itt typestore")
    return str(name)


class Publisher:
    """Publishes messages (or CDR bytes) on one topic."""

    def __init__(self, writer: RawWriter, msg_type: Any) -> None:
        self._writer = writer
        self.msg_type = msg_type
        self.topic_name = writer.ros_name

    @property
    def topic(self) -> str:
        """Fully qualified topic name."""
        return self.topic_name

    def publish(self, msg: Any) -> None:
        """Publish a message of the publisher's type, or its CDR bytes.

        Raises:
            TypeError: a message of another type.
            cyclonedds.core.DDSException: Cyclone refused the bytes.
        """
        if isinstance(msg, bytes | bytearray | memoryview):
            self._writer.write(bytes(msg))
            return
        if getattr(type(msg), "__msgtype__", None) != self._writer.msgtype:
            raise TypeError(f"{self.topic_name} takes {self._writer.msgtype}, "
                            f"not {type(msg).__name__}")
        self._writer.write(serialize(msg))

    def get_subscription_count(self) -> int:
        """Matched subscriptions (local and remote)."""
        return self._writer.matched_count()


class Subscription:
    """Calls `callback` with each received message (or its CDR bytes when `raw`)."""

    def __init__(self, node: Node, topic: str, msg_type: Any, callback: Callable[[Any], None],
                 qos: QoSProfile, group: CallbackGroup, raw: bool) -> None:
        self.msg_type = msg_type
        self.topic_name = topic
        self.callback = callback
        self.callback_group = group
        self.raw = raw
        self._msgtype = _msgtype(msg_type)
        self._ready = threading.Event()
        self._node = node
        self._reader = RawReader(node.context.participant, topic, self._msgtype, qos.plain(),
                                 on_data=self._on_data)
        # Data that arrived before the listener was attached is signalled too.
        self._ready.set()

    def _on_data(self) -> None:
        self._ready.set()
        self._node._wake()

    def is_ready(self) -> bool:
        """Whether data may be waiting."""
        return self._ready.is_set()

    def execute(self) -> None:
        """Take what is queued and run the callback for each sample.

        A payload rosbags cannot decode (non-UTF-8 string, ...) is counted on the node and
        logged; it never escapes into the executor.
        """
        self._ready.clear()
        for sample in self._reader.take():
            if self.raw:
                self.callback(sample.data)
                continue
            try:
                msg = typestore.deserialize_cdr(sample.data, self._msgtype)
            except Exception as err:  # noqa: BLE001  (a corrupt payload raises many types)
                self._node._count_undecodable(self.topic_name, err)
                continue
            self.callback(msg)

    def get_publisher_count(self) -> int:
        """Matched publishers."""
        return self._reader.matched_count()


class Timer:
    """Calls `callback` every `period_ns` of `clock` time; missed periods are skipped."""

    def __init__(self, node: Node, period_ns: int, callback: Callable[[], None],
                 group: CallbackGroup, clock: Clock) -> None:
        self.timer_period_ns = period_ns
        self.callback = callback
        self.callback_group = group
        self.clock = clock
        self._node = node
        self._canceled = False
        self._next_ns = clock.now().nanoseconds + period_ns

    def is_canceled(self) -> bool:
        """Whether `cancel` was called."""
        return self._canceled

    def cancel(self) -> None:
        """Stop calling back."""
        self._canceled = True

    def reset(self) -> None:
        """Restart the period from now."""
        self._canceled = False
        self._next_ns = self.clock.now().nanoseconds + self.timer_period_ns
        self._node._wake()

    def time_until_next_call(self) -> int | None:
        """Nanoseconds of clock time to the next call (<= 0: due), None when cancelled."""
        if self._canceled:
            return None
        return self._next_ns - self.clock.now().nanoseconds

    def is_ready(self) -> bool:
        """Whether the timer is due."""
        remaining = self.time_until_next_call()
        return remaining is not None and remaining <= 0

    def execute(self) -> None:
        """Run the callback and schedule the next call, skipping missed periods (as rcl)."""
        now = self.clock.now().nanoseconds
        if now < self._next_ns - self.timer_period_ns:  # sim time jumped back (log looped)
            self._next_ns = now + self.timer_period_ns
        else:
            self._next_ns += self.timer_period_ns
            if self._next_ns <= now:
                self._next_ns = now + self.timer_period_ns - (now - self._next_ns) % (
                    self.timer_period_ns)
        self.callback()


class Node:
    """A ROS 2 node on the DDS layer (see the module docstring).

    Args:
        node_name: the node's name (`-r __node:=` renames it).
        namespace: the node's namespace (`-r __ns:=` overrides it), default `/`.
        parameter_overrides: values that win over declared defaults and YAML files.
        automatically_declare_parameters_from_overrides: declare every override.

    Raises:
        RuntimeError: the context was not initialised.
    """

    def __init__(self, node_name: str, *, context: Context | None = None,
                 namespace: str | None = None,
                 parameter_overrides: list[Parameter] | None = None,
                 automatically_declare_parameters_from_overrides: bool = False,
                 **_unused: Any) -> None:
        self.context = context or default_context
        args = self.context.ros_args
        self._name = args.remaps.get("__node", node_name)
        self._namespace = normalize_namespace(args.remaps.get("__ns", namespace or "/")) or "/"
        self._logger = get_logger(self._name)
        self._lock = threading.Lock()
        self._wakers: list[Callable[[], None]] = []
        self.publishers: list[Publisher] = []
        self.subscriptions: list[Subscription] = []
        self.timers: list[Timer] = []
        self.default_callback_group: CallbackGroup = MutuallyExclusiveCallbackGroup()
        self.undecodable: dict[str, int] = {}
        self._parameters: dict[str, Parameter] = {}
        self._overrides = self._collect_overrides(parameter_overrides or [])
        self._clock = ROSClock()
        self._clock.add_time_listener(self._wake)
        self._clock_sub: Subscription | None = None
        if automatically_declare_parameters_from_overrides:
            for name, value in self._overrides.items():
                if name != "use_sim_time":
                    self.declare_parameter(name, value)
        use_sim_time = self.declare_parameter("use_sim_time", False).value
        if use_sim_time:
            self._enable_sim_time()

    # --- names and parameters ------------------------------------------------------

    def get_name(self) -> str:
        """The node's name."""
        return self._name

    def get_namespace(self) -> str:
        """The node's namespace (`/` for the root)."""
        return self._namespace

    def get_fully_qualified_name(self) -> str:
        """Namespace + name."""
        return f"{self._namespace.rstrip('/')}/{self._name}"

    def resolve_topic_name(self, topic: str) -> str:
        """Fully qualified topic name (relative names go into the namespace).

        Raises:
            ValueError: an invalid name.
        """
        if topic.startswith("~"):
            topic = self.get_fully_qualified_name() + topic[1:]
        elif not topic.startswith("/"):
            topic = f"{self._namespace.rstrip('/')}/{topic}"
        return self.context.ros_args.remaps.get(topic, topic)

    def _collect_overrides(self, explicit: list[Parameter]) -> dict[str, Any]:
        """YAML files, then `-p` items, then the constructor's overrides (last one wins)."""
        values: dict[str, Any] = {}
        for path in self.context.ros_args.params_files:
            values.update(self._params_from_yaml(Path(path)))
        values.update(self.context.ros_args.overrides)
        values.update({p.name: p.value for p in explicit})
        return values

    def _params_from_yaml(self, path: Path) -> dict[str, Any]:
        """The `ros__parameters` of this node in a ROS 2 parameter file.

        Keys that match: `/**`, the node name, or the fully qualified name (with or
        without the leading `/`), as rcl does.

        Raises:
            ValueError: the file is missing or is not a ROS 2 parameter file.
        """
        try:
            doc = yaml.safe_load(path.read_text(encoding="utf-8"))
        except (OSError, yaml.YAMLError) as err:
            raise ValueError(f"{path}: cannot read the parameter file ({err})") from None
        if not isinstance(doc, dict):
            raise ValueError(f"{path}: not a ROS 2 parameter file (no node keys)")
        fq = self.get_fully_qualified_name()
        wanted = {"/**", self._name, fq, fq.lstrip("/")}
        values: dict[str, Any] = {}
        for key, body in doc.items():
            if str(key) in wanted and isinstance(body, dict):
                params = body.get("ros__parameters")
                if not isinstance(params, dict):
                    raise ValueError(f"{path}: {key} has no ros__parameters mapping")
                values.update(_flatten(params))
        return values

    def declare_parameter(self, name: str, value: Any = None, descriptor: Any = None,
                          ignore_override: bool = False) -> Parameter:
        """Declare `name` with a default; an override (YAML, `-p`, constructor) wins.

        Raises:
            ParameterAlreadyDeclaredException: declared before.
            TypeError: the override's type differs from the default's.
        """
        with self._lock:
            if name in self._parameters:
                raise ParameterAlreadyDeclaredException(name)
            chosen = value
            if not ignore_override and name in self._overrides:
                chosen = self._overrides[name]
                if value is not None and isinstance(value, float) and isinstance(chosen, int) \
                        and not isinstance(chosen, bool):
                    chosen = float(chosen)  # YAML `5` for a float parameter, as rcl allows
                if value is not None and chosen is not None and \
                        Parameter.Type.from_parameter_value(value) != \
                        Parameter.Type.from_parameter_value(chosen):
                    raise TypeError(f"parameter {name}: {chosen!r} does not have the type "
                                    f"of its default {value!r}")
            param = Parameter(name, value=chosen)
            self._parameters[name] = param
            return param

    def declare_parameters(self, namespace: str,
                           parameters: Iterable[tuple[str, Any]]) -> list[Parameter]:
        """Declare several `(name, default)` pairs under `namespace.`."""
        prefix = f"{namespace}." if namespace else ""
        return [self.declare_parameter(prefix + name, value) for name, value in parameters]

    def has_parameter(self, name: str) -> bool:
        """Whether `name` was declared."""
        return name in self._parameters

    def get_parameter(self, name: str) -> Parameter:
        """The declared parameter `name`.

        Raises:
            ParameterNotDeclaredException: not declared.
        """
        try:
            return self._parameters[name]
        except KeyError:
            raise ParameterNotDeclaredException(name) from None

    def get_parameters(self, names: Iterable[str]) -> list[Parameter]:
        """Several declared parameters."""
        return [self.get_parameter(n) for n in names]

    # --- clock and logger ----------------------------------------------------------

    def get_clock(self) -> ROSClock:
        """The node's ROS clock (follows `/clock` under `use_sim_time`)."""
        return self._clock

    def get_logger(self) -> RcutilsLogger:
        """The node's logger."""
        return self._logger

    def _enable_sim_time(self) -> None:
        self._clock._set_ros_time_is_active(True)
        clock_type = typestore.types["rosgraph_msgs/msg/Clock"]
        self._clock_sub = self.create_subscription(
            clock_type, CLOCK_TOPIC,
            lambda msg: self._clock.set_ros_time_override(Time.from_msg(msg.clock)),
            qos_profile_clock, callback_group=MutuallyExclusiveCallbackGroup())

    # --- entities ------------------------------------------------------------------

    def create_publisher(self, msg_type: Any, topic: str, qos_profile: QoSProfile | int,
                         **_unused: Any) -> Publisher:
        """A publisher of `msg_type` (a typestore class) on `topic`.

        Raises:
            TypeError: `msg_type` is not a message type of the itt typestore.
        """
        writer = RawWriter(self.context.participant, self.resolve_topic_name(topic),
                           _msgtype(msg_type), as_profile(qos_profile).plain())
        publisher = Publisher(writer, msg_type)
        self.publishers.append(publisher)
        return publisher

    def create_subscription(self, msg_type: Any, topic: str, callback: Callable[[Any], None],
                            qos_profile: QoSProfile | int, *,
                            callback_group: CallbackGroup | None = None, raw: bool = False,
                            **_unused: Any) -> Subscription:
        """A subscription; `callback` gets the message, or its CDR bytes when `raw`.

        Raises:
            TypeError: `msg_type` is not a message type of the itt typestore.
        """
        sub = Subscription(self, self.resolve_topic_name(topic), msg_type, callback,
                           as_profile(qos_profile), callback_group or self.default_callback_group,
                           raw)
        self.subscriptions.append(sub)
        self._wake()
        return sub

    def create_timer(self, timer_period_sec: float, callback: Callable[[], None],
                     callback_group: CallbackGroup | None = None,
                     clock: Clock | None = None) -> Timer:
        """A timer on the node's clock (sim time under `use_sim_time`, as rclpy).

        Raises:
            ValueError: a period that is not positive.
        """
        if not timer_period_sec > 0:
            raise ValueError(f"timer period must be > 0 s, got {timer_period_sec}")
        timer = Timer(self, round(timer_period_sec * 1e9), callback,
                      callback_group or self.default_callback_group, clock or self._clock)
        self.timers.append(timer)
        self._wake()
        return timer

    def destroy_timer(self, timer: Timer) -> bool:
        """Cancel and forget a timer."""
        timer.cancel()
        if timer in self.timers:
            self.timers.remove(timer)
            return True
        return False

    def destroy_node(self) -> None:
        """Forget every entity (Cyclone frees the DDS entities with the objects)."""
        for timer in self.timers:
            timer.cancel()
        self.timers.clear()
        self.subscriptions.clear()
        self.publishers.clear()

    # --- executor hooks ------------------------------------------------------------

    def _add_waker(self, waker: Callable[[], None]) -> None:
        with self._lock:
            self._wakers.append(waker)

    def _remove_waker(self, waker: Callable[[], None]) -> None:
        with self._lock:
            if waker in self._wakers:
                self._wakers.remove(waker)

    def _wake(self) -> None:
        for waker in list(self._wakers):
            waker()

    def _count_undecodable(self, topic: str, err: Exception) -> None:
        with self._lock:
            self.undecodable[topic] = self.undecodable.get(topic, 0) + 1
        self._logger.warning(f"undecodable message on {topic} dropped ({err})",
                             throttle_duration_sec=5.0)


def _flatten(params: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested YAML mappings become dotted names, as ROS 2 parameter files define."""
    flat: dict[str, Any] = {}
    for key, value in params.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(_flatten(value, f"{name}."))
        else:
            flat[name] = value
    return flat
