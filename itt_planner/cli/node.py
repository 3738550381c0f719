"""`itt-planner node | play | record`: the pacing node and bag-like tools without ROS.

`node` runs `itt_planner_ros.pacing_node` on real rclpy if installed, else on the DDS
layer; `play` and `record` work like `ros2 bag play` / `ros2 bag record` on the DDS
layer (ROS 2 wire conventions, so ROS 2 nodes on `rmw_cyclonedds_cpp` see them too).
Cyclone uses the shipped loopback-only configuration unless `CYCLONEDDS_URI` is set;
the domain is `ROS_DOMAIN_ID`.
"""

from __future__ import annotations

import logging
import os
import signal
import sys
import threading
from pathlib import Path
from typing import Any

import typer

from itt_planner.cli._app import JSON_OPTION, app, emit, errors_to_exit
from itt_planner.errors import IttError


def _log_to_stderr() -> None:
    """Node, player and recorder report on stderr in ROS 2's console format."""
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="[%(levelname)s] [%(created).3f] [%(name)s]: %(message)s")


def _stop_on_signals() -> threading.Event:
    """An event set by SIGINT/SIGTERM, so play/record finish their files cleanly."""
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda _s, _f: stop.set())
    return stop


def _participant() -> Any:
    from itt_planner.dds.context import default_context

    default_context.init([])
    return default_context.participant


@app.command("node")
def node_cli(
    course: str = typer.Option(None, "--course", help="Course: demo name, GPS track, .course.npz."),
    rider: str = typer.Option(None, "--rider", help="Rider preset or YAML file."),
    params: Path = typer.Option(None, "--params", exists=True, dir_okay=False,
                                help="ROS 2 parameter YAML (config/params.yaml format)."),
    namespace: str = typer.Option("/itt", "--namespace", help="ROS namespace of the topics."),
    runtime: str = typer.Option("auto", "--runtime", help="auto | rclpy | dds."),
    use_sim_time: bool = typer.Option(False, "--use-sim-time", help="Follow /clock."),
    output_log: Path = typer.Option(None, "--output-log", help="MCAP log of inputs and outputs."),
    state_file: Path = typer.Option(None, "--state-file", help="W' state file (resume)."),
    rerun: str = typer.Option(None, "--rerun", help="Rerun sink: file:X.rrd, spawn, ..."),
    replan_period_s: float = typer.Option(None, "--replan-period", help="Replan period (s)."),
    plan: Path = typer.Option(None, "--plan", help="Saved full-course plan (Plan.save)."),
    plan_cache: Path = typer.Option(None, "--plan-cache", help="Plan cache directory."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Run the pacing node until Ctrl-C (rclpy if installed, else Cyclone DDS)."""
    with errors_to_exit(as_json):
        if runtime not in ("auto", "rclpy", "dds"):
            raise typer.BadParameter("expected auto, rclpy or dds", param_hint="--runtime")
        _log_to_stderr()
        os.environ["ITT_RUNTIME"] = runtime  # read when the node module is imported
        from itt_planner_ros import pacing_node

        given = {"course": course, "rider": rider, "use_sim_time": use_sim_time or None,
                 "output_log": output_log, "state_file": state_file, "rerun_sink": rerun,
                 "replan_period_s": replan_period_s, "plan": plan, "plan_cache": plan_cache}
        overrides = [pacing_node.Parameter(k, value=str(v) if isinstance(v, Path) else v)
                     for k, v in given.items() if v is not None]
        args = ["--ros-args", "--params-file", str(params)] if params else []
        result = pacing_node.run(args, namespace=namespace, parameter_overrides=overrides)
        if not result:
            raise IttError("the node did not start")
    emit(result, as_json, lambda r: (f"{r['advice_published']} advice published "
                                     f"({r['runtime']}); malformed payloads: "
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
        0.0, "--wait-for-matched", help="Wait up to s for subscribers of the input topics."),
    namespace: str = typer.Option("/itt", "--namespace", help="Namespace of the log's topics."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Publish a ride log on DDS like `ros2 bag play`."""
    with errors_to_exit(as_json):
        from itt_planner.dds.player import Player, PlaySettings

        _log_to_stderr()
        stop = _stop_on_signals()
        settings = PlaySettings(rate=rate, loop=loop, clock_hz=clock_hz if clock else 0.0,
                                start_offset_s=start_offset_s, topics=tuple(topic),
                                wait_for_matched_s=wait_for_matched_s, namespace=namespace)
        stats = Player(log, _participant(), settings).play(stop)
    result = {"log": str(log), "messages": dict(stats.messages),
              "published": stats.messages.total(), "loops": stats.loops,
              "clock_messages": stats.clock_messages, "refused": stats.refused,
              "log_errors": stats.log_errors}
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
    """Record DDS topics to an MCAP file like `ros2 bag record` (until Ctrl-C)."""
    with errors_to_exit(as_json):
        from itt_planner.dds.recorder import Recorder, RecordSettings

        _log_to_stderr()
        if not topics and not all_topics:
            raise typer.BadParameter("name topics or use -a")
        stop = _stop_on_signals()
        recorder = Recorder(output, _participant(),
                            RecordSettings(topics=tuple(topics or ()), all_topics=all_topics,
                                           use_sim_time=use_sim_time))
        counts = recorder.run(stop, duration_s)
    result = {"output": str(output), "messages": dict(counts), "recorded": counts.total()}
    emit(result, as_json, lambda r: f"recorded {r['recorded']} messages to {r['output']}")
