"""`itt-planner node | play | record`: the pacing node, and bag tools, on real rclpy.

`node` runs `itt_planner_ros.pacing_node` (the same node `ros2 run` / `ros2 launch`
start) with the parameter file and `--ros-args` given; `play` and `record` work like
`ros2 bag play` / `ros2 bag record` (which are not on PyPI) on the project's MCAP
reader and writer. ROS is imported only inside these commands: the rest of the CLI and
the core run without it.
"""

from __future__ import annotations

import logging
import sys
import threading
from pathlib import Path

import typer

from itt_planner.cli._app import JSON_OPTION, app, emit, errors_to_exit
from itt_planner.errors import IttError


def _ros() -> None:
    """Raise set-up's one-line reason when rclpy or the built messages do not import."""
    from itt_msgs_py.dds_env import ros_unavailable_reason  # noqa: PLC0415

    reason = ros_unavailable_reason()
    if reason is not None:
        raise IttError(f"{reason}; elsewhere use the Docker image (see the README)")


def _log_to_stderr() -> None:
    """The core's log lines on stderr, in ROS 2's console format."""
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="[%(levelname)s] [%(created).3f] [%(name)s]: %(message)s")


def _stop_event() -> threading.Event:
    """An event SIGINT/SIGTERM set, so play/record finish their files cleanly (and the
    stacks on `signals.STACKS_SIGNAL`)."""
    from itt_planner_ros.signals import handle_signals  # noqa: PLC0415

    stop = threading.Event()
    handle_signals(stop)
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
    plan: Path = typer.Option(None, "--plan", help="Saved full-course plan (Plan.save)."),
    plan_cache: Path = typer.Option(None, "--plan-cache", help="Plan cache directory."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Run the pacing node on rclpy until Ctrl-C; arguments after `--ros-args` go to ROS."""
    with errors_to_exit(as_json):
        _ros()
        _log_to_stderr()
        from itt_planner_ros import pacing_node  # noqa: PLC0415
        from rclpy.parameter import Parameter  # noqa: PLC0415

        given = {"course": course, "rider": rider, "use_sim_time": use_sim_time or None,
                 "output_log": output_log, "state_file": state_file, "rerun_sink": rerun,
                 "plan": plan, "plan_cache": plan_cache}
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


@app.command("play")
def play_cli(
    log: Path = typer.Argument(..., exists=True, dir_okay=False, help="Ride log (.mcap)."),
    rate: float = typer.Option(1.0, "--rate", "-r", help="Playback speed factor."),
    loop: bool = typer.Option(False, "--loop", "-l", help="Loop until Ctrl-C."),
    clock: bool = typer.Option(False, "--clock", help="Publish /clock (for use_sim_time)."),
    clock_hz: float = typer.Option(40.0, "--clock-hz", help="/clock rate (wall Hz)."),
    start_offset_s: float = typer.Option(0.0, "--start-offset", help="Skip the first s."),
    topic: list[str] = typer.Option([], "--topics", help="Only these topics (repeat)."),
    wait_for_matched_s: float = typer.Option(
        0.0, "--wait-for-matched",
        help="Wait up to s for subscribers of the input topics (and of /clock with --clock)."),
    delay_s: float = typer.Option(
        0.0, "--delay", "-d", min=0.0,
        help="Then hold the first message back s (ros2 bag play --delay; /clock holds the "
             "start time): for subscribers that match late, which the wait cannot see."),
    namespace: str = typer.Option("/itt", "--namespace", help="Namespace of the log's topics."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Publish a ride log on ROS 2 like `ros2 bag play` (the log's QoS, optional /clock)."""
    with errors_to_exit(as_json):
        _ros()
        _log_to_stderr()
        from itt_planner_ros.player import PlaySettings, play  # noqa: PLC0415

        settings = PlaySettings(rate=rate, loop=loop, clock_hz=clock_hz if clock else 0.0,
                                start_offset_s=start_offset_s, topics=tuple(topic),
                                wait_for_matched_s=wait_for_matched_s, delay_s=delay_s,
                                namespace=namespace)
        stats = play(log, settings, _stop_event())
    result = {"log": str(log), **stats.as_dict()}
    emit(result, as_json, lambda r: f"published {r['published']} messages from {r['log']}")


@app.command("record")
def record_cli(
    topics: list[str] = typer.Argument(None, help="Topics to record (fully qualified)."),
    output: Path = typer.Option(..., "--output", "-o", help="The .mcap file to write."),
    all_topics: bool = typer.Option(False, "--all", "-a", help="Record every ROS topic."),
    use_sim_time: bool = typer.Option(False, "--use-sim-time", help="Log times from /clock."),
    duration_s: float = typer.Option(None, "--duration", help="Stop after s (wall)."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Record ROS 2 topics to an MCAP file like `ros2 bag record` (until Ctrl-C)."""
    with errors_to_exit(as_json):
        _ros()
        _log_to_stderr()
        from itt_planner_ros.recorder import RecordSettings, record  # noqa: PLC0415

        if not topics and not all_topics:
            raise typer.BadParameter("name topics or use -a")
        settings = RecordSettings(topics=tuple(topics or ()), all_topics=all_topics,
                                  use_sim_time=use_sim_time)
        stats = record(output, settings, _stop_event(), duration_s)
    result = {"output": str(output), **stats.as_dict()}
    emit(result, as_json, lambda r: f"recorded {r['recorded']} messages to {r['output']}")
