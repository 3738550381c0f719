"""The rclpy API subset of the DDS layer (see `itt_planner.dds`).

Use it where `rclpy` would be imported: `rclpy.init()`, `rclpy.spin(node)`,
`rclpy.node.Node`, `rclpy.executors.MultiThreadedExecutor`, `rclpy.qos...`.
"""

from __future__ import annotations

import logging as pylogging
import sys

from itt_planner.dds.context import Context, default_context, install_signal_handlers
from itt_planner.dds.rclpy import (
    callback_groups,
    clock,
    clock_type,
    duration,
    executors,
    logging,
    node,
    parameter,
    qos,
    time,
)

__all__ = [
    "callback_groups", "clock", "clock_type", "create_node", "duration", "executors", "init",
    "logging", "node", "ok", "parameter", "qos", "shutdown", "spin", "spin_once", "time",
    "try_shutdown",
]


def init(*, args: list[str] | None = None, context: Context | None = None,
         domain_id: int | None = None, signal_handler_options: object = None) -> None:
    """Join the DDS domain and read `--ros-args`; SIGINT/SIGTERM shut down (as rclpy).

    Raises:
        RuntimeError: called twice without `shutdown`.
        ValueError: malformed ROS arguments.
    """
    ctx = context or default_context
    ctx.init(args, domain_id)
    if not pylogging.getLogger().handlers:  # rclpy logs INFO to the console by default
        pylogging.basicConfig(level=pylogging.INFO, stream=sys.stderr,
                              format="[%(levelname)s] [%(created).3f] [%(name)s]: %(message)s")
    if signal_handler_options is not False:
        install_signal_handlers(ctx)


def ok(*, context: Context | None = None) -> bool:
    """True between `init` and `shutdown`."""
    return (context or default_context).ok()


def shutdown(*, context: Context | None = None) -> None:
    """Shut the context down: spinning executors return.

    Raises:
        RuntimeError: not initialised.
    """
    (context or default_context).shutdown()


def try_shutdown(*, context: Context | None = None) -> None:
    """`shutdown` unless already shut down."""
    (context or default_context).try_shutdown()


def create_node(node_name: str, **kwargs: object) -> node.Node:
    """A plain `Node`."""
    return node.Node(node_name, **kwargs)  # type: ignore[arg-type]


def spin(node_: node.Node, executor: executors.Executor | None = None) -> None:
    """Spin `node_` until shutdown.

    Raises:
        executors.ExternalShutdownException: shut down from outside.
    """
    ex = executor or executors.SingleThreadedExecutor(context=node_.context)
    ex.add_node(node_)
    try:
        ex.spin()
    finally:
        ex.remove_node(node_)


def spin_once(node_: node.Node, *, executor: executors.Executor | None = None,
              timeout_sec: float | None = None) -> None:
    """Run what is ready on `node_`, or wait up to `timeout_sec`."""
    ex = executor or executors.SingleThreadedExecutor(context=node_.context)
    ex.add_node(node_)
    try:
        ex.spin_once(timeout_sec)
    finally:
        ex.remove_node(node_)
