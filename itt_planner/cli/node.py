"""`itt-planner node | play | record`: the pacing node, and bag tools, on real rclpy.

`node` runs `itt_planner_ros.pacing_node` (the same node `ros2 run` / `ros2 launch`
start) with the parameter file and `--ros-args` given; `play` and `record` work like
`ros2 bag play` / `ros2 bag record` (which are not on PyPI) on the project's MCAP
reader and writer. ROS is imported only inside these commands: the rest of the CLI and
the core run without it.
"""

from __future__ import annotations

import logging
import signal
import sys
import threading
from pathlib import Path
from typing import Any

import typer

from itt_planner.cli._app import JSON_OPTION, app, emit, errors_to_exit
from itt_planner.errors import IttError

#: Why ROS commands cannot run, when rclpy or the built messages are missing.
NO_ROS = ("real ROS 2 (rclpy and the itt_msgs interfaces) is not installed in this Python: "
          "`make test`/`make demo` install it on x86_64 Linux with CPython 3.11-3.13; "
          "elsewhere use the Docker image")


def _ros() -> None:
    """Raise a clear error when rclpy or the project's built messages do not import."""
    try:
        import itt_msgs.msg  # noqa: F401,PLC0415
        import rclpy  # noqa: F401,PLC0415
    except ImportError as err:
        raise IttError(f"{NO_ROS} ({err})") from None


def _log_to_stderr() -> None:
    """The core's log lines on stderr, in ROS 2's console format."""
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="[%(levelname)s] [%(created).3f] [%(name)s]: %(message)s")


def _stop_on_signals() -> threading.Event:
    """An event set by SIGINT/SIGTERM, so play/record finish their files cleanly."""
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda _s, _f: stop.set())
    return stop


@app.command("node", context_settings={"allow_extra_args": True,
                                       "ignore_unknown_options": True})
def node_cli(
    ctx: typer.Context,
    params_file: Path = typer.Option(
        None, "--params-file", exists=True, dir_okay=False,
        help="ROS 2 parameter YAML (the launch file's config/params.yaml format)."),
    course: str = typer.Option(None, "--course", help="Course: demo name, GPS track, .course.npz."),
    rider: str = typer.Option(None, "--rider", help="Rider preset or YAML file."),
    namespace: str = typer.Option("/itt", "--namespace", help="ROS namespace of the topics."),
    use_sim_time: bool = typer.Option(False, "--use-sim-time", help="Follow /clock."),
    output_log: Path = typer.Option(None, "--output-log", help="MCAP log of inputs and outputs."),
    state_file: Path = typer.Option(None, "--state-file", help="W' state file (resume)."),
    rerun: str = typer.Option(None, "--rerun", help="Rerun sink: file:X.rrd, spawn, ..."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Run the pacing node on rclpy until Ctrl-C; arguments after `--ros-args` go to ROS."""
    with errors_to_exit(as_json):
        _ros()
        _log_to_stderr()
        from rclpy.parameter import Parameter  # noqa: PLC0415

        from itt_planner_ros import pacing_node  # noqa: PLC0415

        given = {"course": course, "rider": rider, "use_sim_time": use_sim_time or None,
                 "output_log": output_log, "state_file": state_file, "rerun_sink": rerun}
        overrides = [Parameter(k, value=str(v) if isinstance(v, Path) else v)
                     for k, v in given.items() if v is not None]
        ros_args = list(ctx.args)
        if params_file is not None:
            if "--ros-args" not in ros_args:
                ros_args.append("--ros-args")
            at = ros_args.index("--ros-args") + 1
            ros_args[at:at] = ["--params-file", str(params_file)]
        result = pacing_node.run(ros_args, namespace=namespace, parameter_overrides=overrides)
        if not result:
            raise IttError("the node was stopped before it was ready")
    emit(result, as_json, lambda r: (f"{r['advice_out']} advice published "
                                     f"({r['fallbacks']} fallbacks); malformed input: "
                                     f"{sum(r['malformed'].values())}"))
