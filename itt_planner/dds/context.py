"""The process-wide DDS state: participant, command-line ROS arguments, shutdown.

The participant joins domain `ROS_DOMAIN_ID` (default 0, as ROS 2). Unless the caller
set `CYCLONEDDS_URI`, Cyclone is configured with the shipped
`itt_msgs_py/cyclonedds.xml` (loopback only, multicast off, peer 127.0.0.1), so a local
run never sends a packet off the machine.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib.resources import files
from typing import Any

from cyclonedds.domain import DomainParticipant

CONFIG_ENV = "CYCLONEDDS_URI"
DOMAIN_ENV = "ROS_DOMAIN_ID"


def shipped_config_uri() -> str:
    """`file://` URI of the Cyclone configuration shipped with `itt_msgs_py`."""
    return "file://" + str(files("itt_msgs_py") / "cyclonedds.xml")


def use_shipped_config_by_default() -> None:
    """Point `CYCLONEDDS_URI` at the shipped loopback config unless it is already set."""
    os.environ.setdefault(CONFIG_ENV, shipped_config_uri())


@dataclass
class RosArgs:
    """What `--ros-args ...` on the command line asked for (the subset we honour).

    Attributes:
        params_files: `--params-file FILE` (ROS 2 parameter YAML).
        overrides: `-p name:=value` (value parsed as YAML, as ROS 2 does).
        remaps: `-r from:=to`; `__ns` and `__node` rename the node.
    """

    params_files: list[str] = field(default_factory=list)
    overrides: dict[str, Any] = field(default_factory=dict)
    remaps: dict[str, str] = field(default_factory=dict)


def parse_ros_args(args: list[str] | None) -> RosArgs:
    """Parse the `--ros-args` section of `args` (everything else is not ours).

    Raises:
        ValueError: a malformed `-p`/`-r` item or a flag without its value.
    """
    import yaml

    parsed = RosArgs()
    if not args or "--ros-args" not in args:
        return parsed
    items = iter(args[args.index("--ros-args") + 1:])
    for item in items:
        if item == "--":
            break
        if item in ("--params-file", "-p", "--param", "-r", "--remap"):
            value = next(items, None)
            if value is None:
                raise ValueError(f"{item} needs a value")
            if item == "--params-file":
                parsed.params_files.append(value)
                continue
            name, sep, rhs = value.partition(":=")
            if not sep or not name:
                raise ValueError(f"{item} {value!r}: expected name:=value")
            if item in ("-p", "--param"):
                parsed.overrides[name] = yaml.safe_load(rhs)
            else:
                parsed.remaps[name] = rhs
    return parsed


class Context:
    """One rclpy-like context: `init` creates the participant, `shutdown` stops spinning."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._participant: DomainParticipant | None = None
        self._ok = False
        self._on_shutdown: list[Callable[[], None]] = []
        self.ros_args = RosArgs()
        self.domain_id = 0

    def init(self, args: list[str] | None = None, domain_id: int | None = None) -> None:
        """Start: parse ROS arguments and join the DDS domain.

        Raises:
            RuntimeError: already initialised.
            ValueError: malformed ROS arguments or `ROS_DOMAIN_ID`.
        """
        with self._lock:
            if self._ok:
                raise RuntimeError("rclpy.init() called twice without shutdown()")
            # As rclpy: without explicit args, the process's command line is parsed.
            self.ros_args = parse_ros_args(sys.argv if args is None else args)
            self.domain_id = (domain_id if domain_id is not None
                              else int(os.environ.get(DOMAIN_ENV, "0") or 0))
            use_shipped_config_by_default()
            self._participant = DomainParticipant(self.domain_id)
            self._ok = True
            self._on_shutdown = []

    @property
    def participant(self) -> DomainParticipant:
        """The DDS participant of this context.

        Raises:
            RuntimeError: `init` was not called.
        """
        if self._participant is None:
            raise RuntimeError("rclpy.init() has not been called")
        return self._participant

    def ok(self) -> bool:
        """True between `init` and `shutdown`."""
        return self._ok

    def on_shutdown(self, callback: Callable[[], None]) -> None:
        """Run `callback` when the context shuts down (executors wake up on it)."""
        with self._lock:
            self._on_shutdown.append(callback)

    def shutdown(self) -> None:
        """Stop: every spinning executor returns. The participant lives until exit.

        Raises:
            RuntimeError: not initialised.
        """
        with self._lock:
            if not self._ok:
                raise RuntimeError("rclpy.shutdown() called without init()")
            self._ok = False
            callbacks, self._on_shutdown = self._on_shutdown, []
        for callback in callbacks:
            callback()

    def try_shutdown(self) -> None:
        """`shutdown` if still running."""
        if self._ok:
            self.shutdown()


default_context = Context()


def install_signal_handlers(context: Context) -> None:
    """SIGINT/SIGTERM shut the context down (as rclpy's handlers do), main thread only."""
    if threading.current_thread() is not threading.main_thread():
        return

    def handler(signum: int, _frame: object) -> None:
        context.try_shutdown()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
