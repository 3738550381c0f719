"""The pacing node on the DDS layer: in one process, and as `itt-planner` processes on
the loopback interface (play -> node -> record), with the faults of issue 6."""

from __future__ import annotations

import json
import math
import signal
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from dds_support import RIDE_T0_S, Proc, Ride, cached_ride, cli, dds_env, random_domain
from mcap_readers import rosbags_messages
from rosbags.highlevel import AnyReader

from itt_msgs_py import serialize, topics, typestore
from itt_msgs_py.convert import msg_to_advice, msg_to_diagnostics, sample_to_msg
from itt_planner.dds.context import Context
from itt_planner.dds.rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from itt_planner.dds.rclpy.node import Node
from itt_planner.dds.rclpy.parameter import Parameter
from itt_planner.dds.rclpy.qos import QoSProfile, ReliabilityPolicy
from itt_planner.ridelog import read_ride_log
from itt_planner.samples import GpsFix


@pytest.fixture(scope="module")
def ride(tmp_path_factory: pytest.TempPathFactory) -> Ride:
    return cached_ride(tmp_path_factory.getbasetemp())


def _qos(topic: topics.Topic) -> QoSProfile:
    return QoSProfile(depth=topic.qos.depth, reliability=(
        ReliabilityPolicy.BEST_EFFORT if topic.qos.reliability is topics.Reliability.BEST_EFFORT
        else ReliabilityPolicy.RELIABLE))


class Spinner:
    """Nodes of one context spun by a MultiThreadedExecutor on a background thread."""

    def __init__(self, context: Context, *nodes: Node) -> None:
        self.context = context
        self.executor = MultiThreadedExecutor(num_threads=4, context=context)
        for node in nodes:
            self.executor.add_node(node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.error: BaseException | None = None
        self.thread.start()

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except ExternalShutdownException:
            pass
        except BaseException as err:  # noqa: BLE001  (reported by stop())
            self.error = err

    def stop(self) -> None:
        self.context.shutdown()
        self.thread.join(10)
        self.executor.shutdown()
        assert self.error is None, self.error


def _wait(predicate: Any, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.05)
    return False


def test_node_turns_inputs_into_advice_and_survives_malformed_payloads(
        ride: Ride, tmp_path: Path) -> None:
    from itt_planner_ros.pacing_node import PacingNode

    ctx = Context()
    ctx.init([], random_domain())
    node = PacingNode(context=ctx, parameter_overrides=[
        Parameter("course", value=str(ride.course)), Parameter("plan", value=str(ride.plan)),
        Parameter("state_file", value=str(tmp_path / "state.json")),
        Parameter("tick_period_s", value=0.05),
        Parameter("output_log", value=str(tmp_path / "node.mcap")),
        Parameter("rerun_sink", value=f"file:{tmp_path / 'node.rrd'}")])
    assert node.get_namespace() == "/itt"
    feeder = Node("feeder", context=ctx, namespace="/itt")
    pubs = {t.key: feeder.create_publisher(typestore.types[t.msgtype], t.key, _qos(t))
            for t in topics.INPUT_TOPICS}
    got: dict[str, list[Any]] = {"advice": [], "diag": []}
    feeder.create_subscription(typestore.types[topics.ADVICE.msgtype], "advice",
                               got["advice"].append, _qos(topics.ADVICE))
    feeder.create_subscription(typestore.types[topics.DIAGNOSTICS.msgtype], "/diagnostics",
                               got["diag"].append, _qos(topics.DIAGNOSTICS))
    spinner = Spinner(ctx, node, feeder)
    try:
        assert _wait(lambda: all(p.get_subscription_count() for p in pubs.values()), 5)
        bad_utf8 = nan_fixes = 0
        start = time.monotonic()
        for _topic, stamp, sample in read_ride_log(ride.log):
            if stamp > RIDE_T0_S + 60:
                break
            time.sleep(max(0.0, start + (stamp - RIDE_T0_S) / 10 - time.monotonic()))
            topic, msg = sample_to_msg(sample)
            data = serialize(msg)
            pubs[topic.key].publish(data)
            if isinstance(sample, GpsFix) and int(stamp) % 10 == 5:
                # Valid CDR for DDS, but the frame_id is not UTF-8: rosbags must refuse it.
                pubs[topic.key].publish(data.replace(b"gps\x00", b"\xff\xfe\xfd\x00"))
                bad_utf8 += 1
            if isinstance(sample, GpsFix) and int(stamp) % 10 == 7:
                msg.latitude = math.nan  # decodes fine; the engine must reject it
                msg.header.stamp.nanosec += 1000
                pubs[topic.key].publish(msg)
                nan_fixes += 1
        assert _wait(lambda: node.malformed["gps/fix"] == bad_utf8, 5), node.malformed
        assert _wait(lambda: len(got["advice"]) >= 3, 20)
        assert _wait(lambda: any(
            d.name == "itt_planner/node" and d.values.get("malformed/gps/fix") == str(bad_utf8)
            for m in got["diag"] for d in msg_to_diagnostics(m)), 10)
    finally:
        spinner.stop()
        node.close()
    assert bad_utf8 >= 5 and nan_fixes >= 5
    assert node.engine.counters.get("gps_invalid", 0) == nan_fixes
    advice = [msg_to_advice(m) for m in got["advice"]]
    stamps = [a.stamp_s for a in advice]
    assert stamps == sorted(stamps) and RIDE_T0_S < stamps[0] and stamps[-1] <= RIDE_T0_S + 61
    assert all(0 < a.state.s_m < 1000 and len(a.horizon_s_m) > 10 for a in advice)
    saved = json.loads((tmp_path / "state.json").read_text())
    assert saved["engine"]["estimator"]["w_prime_j"] < 22_000  # W' used on the way
    assert (tmp_path / "node.rrd").stat().st_size > 10_000  # Rerun recording written
    # The node's own log: inputs it accepted for decoding, every advice it published.
    info, logged = rosbags_messages(tmp_path / "node.mcap")
    assert info["/itt/advice"] == (topics.ADVICE.msgtype, node.advice_count)
    assert info["/itt/target_line"][1] == node.advice_count
    assert [m.header.stamp for m in logged["/itt/advice"]][:len(got["advice"])] == \
        [m.header.stamp for m in got["advice"]]


def test_sim_time_timers_follow_clock_and_groups_run_in_parallel() -> None:
    """use_sim_time: timers tick on /clock; a slow timer in its own group never blocks a
    subscription (MultiThreadedExecutor)."""
    ctx = Context()
    ctx.init(["--ros-args", "-p", "use_sim_time:=true"], random_domain())
    from itt_planner.dds.rclpy.callback_groups import MutuallyExclusiveCallbackGroup

    node = Node("timers", context=ctx)
    clock_type = typestore.types["rosgraph_msgs/msg/Clock"]
    clock_pub = node.create_publisher(clock_type, "/clock", 1)
    ticks: list[int] = []
    received: list[float] = []

    def slow_tick() -> None:
        ticks.append(node.get_clock().now().nanoseconds)
        time.sleep(0.3)  # a "solve"

    node.create_timer(1.0, slow_tick, callback_group=MutuallyExclusiveCallbackGroup())
    fix_type = typestore.types["sensor_msgs/msg/NavSatFix"]
    pub = node.create_publisher(fix_type, "fix", 10)
    node.create_subscription(fix_type, "fix", lambda m: received.append(time.monotonic()), 10)
    spinner = Spinner(ctx, node)
    time_type = typestore.types["builtin_interfaces/msg/Time"]
    try:
        assert node.get_parameter("use_sim_time").value is True
        assert node.get_clock().now().nanoseconds == 0 and not ticks
        _wait(lambda: clock_pub.get_subscription_count() > 0, 5)
        for k in range(50):  # 5 s of sim time in ~1 s of wall time
            clock_pub.publish(clock_type(clock=time_type(sec=1000 + k // 10,
                                                         nanosec=(k % 10) * 100_000_000)))
            pub.publish(sample_to_msg(GpsFix(float(k), 45.0, 11.0, 0.0))[1])
            time.sleep(0.02)
        _wait(lambda: len(received) >= 50, 5)
    finally:
        spinner.stop()
    assert 2 <= len(ticks) <= 6  # ~1 tick per s of sim time, missed periods skipped
    assert all(1000e9 <= t < 1005e9 for t in ticks)
    assert len(received) == 50
    # Subscription callbacks ran while slow ticks were sleeping: no 0.3 s holes.
    assert float(np.max(np.diff(received))) < 0.25


# ---- multi-process on the loopback interface --------------------------------------------------

def _node_args(ride: Ride, folder: Path, *extra: str) -> list[str]:
    return cli("node", "--course", str(ride.course), "--plan", str(ride.plan),
               "--state-file", str(folder / "state.json"), "--json", *extra)


def _advice_from(path: Path) -> tuple[dict[str, tuple[str, int]], list[Any]]:
    info, msgs = rosbags_messages(path)
    return info, [msg_to_advice(m) for m in msgs.get("/itt/advice", [])]


def test_play_node_record_pipeline_on_loopback(ride: Ride, tmp_path: Path) -> None:
    env = dds_env()
    node = Proc(_node_args(ride, tmp_path, "--use-sim-time"), env, tmp_path / "node.log")
    recorder = Proc(cli("record", "-a", "-o", str(tmp_path / "out.mcap"), "--use-sim-time",
                        "--json"), env, tmp_path / "record.log")
    try:
        node.wait_for("ready on /itt", 120)
        player = Proc(cli("play", str(ride.log), "--rate", "8", "--clock",
                          "--wait-for-matched", "10", "--json"), env, tmp_path / "play.log")
        played = json.loads(player.wait(120))
        time.sleep(1.0)
    finally:
        node_out = node.stop()
        record_out = recorder.stop()
    assert played["refused"] == 0 and played["clock_messages"] > 100
    assert set(played["messages"]) == {"/itt/gps/fix", "/itt/speed", "/itt/power"}
    result = json.loads(node_out)
    assert result["runtime"] == "dds" and result["malformed"] == {}
    assert json.loads(record_out)["recorded"] > 0

    # Every recorded message decodes with rosbags to the type its channel declares.
    info, advice = _advice_from(tmp_path / "out.mcap")
    declared = {t.name(): t.msgtype for t in topics.TOPICS}
    assert {topic: info[topic][0] for topic in declared} == declared
    _, msgs = rosbags_messages(tmp_path / "out.mcap")
    for topic, decoded in msgs.items():
        assert all(m.__msgtype__ == info[topic][0] for m in decoded)
    assert len(msgs["/itt/gps/fix"]) >= 0.9 * played["messages"]["/itt/gps/fix"]
    assert len(msgs["/clock"]) > 100  # ros2 bag record -a records /clock too
    # Recorded with the QoS the publishers offered, as ros2 bag record does.
    with AnyReader([tmp_path / "out.mcap"]) as reader:
        offered = {c.topic: c.ext.offered_qos_profiles[0].reliability.name
                   for c in reader.connections}
    assert offered["/itt/gps/fix"] == "BEST_EFFORT" and offered["/itt/advice"] == "RELIABLE"

    # Advice for the whole ride, on the sim clock.
    assert len(advice) == result["advice_published"] and len(advice) >= 10
    stamps = np.array([a.stamp_s for a in advice]) - RIDE_T0_S
    assert stamps[0] < 20 and stamps[-1] > ride.duration_s - 20
    assert float(np.max(np.diff(stamps))) < 30
    assert advice[-1].state.s_m > 0.9 * 2738
    line = msgs["/itt/target_line"][-1]
    assert line.header.frame_id == "map" and len(line.poses) == len(advice[-1].line_x_m)


def test_faults_player_and_node_restarts(ride: Ride, tmp_path: Path) -> None:
    """Kill the player mid-ride and restart it further on: the node carries on. Kill the
    node (and the player) mid-ride: the restarted node resumes with the W' it persisted."""
    env = dds_env()
    state = tmp_path / "state.json"
    params = tmp_path / "params.yaml"
    params.write_text("/**:\n  ros__parameters:\n    state_period_s: 0.5\n")
    node_args = _node_args(ride, tmp_path, "--params", str(params))
    node = Proc(node_args, env, tmp_path / "node1.log")
    recorder = Proc(cli("record", "-o", str(tmp_path / "out.mcap"), "/itt/advice"), env,
                    tmp_path / "record.log")
    node.wait_for("ready on /itt", 120)
    rate = 8.0
    player = Proc(cli("play", str(ride.log), "--rate", str(rate), "--wait-for-matched", "10"),
                  env, tmp_path / "play1.log")
    time.sleep(0.3 * ride.duration_s / rate)
    player.stop(signal.SIGKILL)  # mid-ride, no goodbye
    time.sleep(1.0)
    offset = 0.4 * ride.duration_s
    player = Proc(cli("play", str(ride.log), "--rate", str(rate), "--start-offset",
                      str(offset)), env, tmp_path / "play2.log")
    started = time.monotonic()
    time.sleep(0.2 * ride.duration_s / rate)
    assert node.popen.poll() is None, node.text()
    # The node dies mid-ride with the player: only the periodic save survives.
    node.stop(signal.SIGKILL)
    player.stop(signal.SIGKILL)
    offset += (time.monotonic() - started) * rate
    killed_at = time.time()
    saved = json.loads(state.read_text())["engine"]["estimator"]
    node = Proc(node_args, env, tmp_path / "node2.log")
    try:
        node.wait_for("resumed from", 120)
        assert f"W' {saved['w_prime_j']:.0f} J" in node.text()
        player = Proc(cli("play", str(ride.log), "--rate", str(rate), "--start-offset",
                          str(offset), "--wait-for-matched", "10"), env, tmp_path / "play3.log")
        player.wait(120)
        time.sleep(1.0)
    finally:
        out = json.loads(node.stop())
        recorder.stop()
    assert out["advice_published"] > 0
    advice = [(t, a) for _topic, t, a in read_ride_log(tmp_path / "out.mcap")]
    first_node = np.array([a.stamp_s for t, a in advice if t < killed_at]) - RIDE_T0_S
    second_node = [a for t, a in advice if t > killed_at]
    # The first node carried on after the player's restart ...
    assert first_node.min() < 0.25 * ride.duration_s
    assert first_node.max() > 0.45 * ride.duration_s
    # ... and the restarted node went on from the persisted W', not from a fresh one.
    fresh = 22_000.0  # W' of the `paper` rider
    assert saved["w_prime_j"] < 0.8 * fresh and second_node
    first = second_node[0]
    assert first.state.s_m >= saved["s_m"] - 50 > 0.3 * 2738  # no jump back to the start
    assert abs(first.w_prime_now_j - saved["w_prime_j"]) < 0.5 * (fresh - saved["w_prime_j"])
    assert second_node[-1].stamp_s - RIDE_T0_S > ride.duration_s - 20


def _flood(ride: Ride, tmp_path: Path, seconds: float) -> None:
    env = dds_env()
    node = Proc(_node_args(ride, tmp_path), env, tmp_path / "node.log")
    node.wait_for("ready on /itt", 120)
    player = Proc(cli("play", str(ride.log), "--rate", "1", "--wait-for-matched", "10",
                      "--json"), env, tmp_path / "play.log")
    rss = []
    deadline = time.monotonic() + 3 * seconds + 30
    while player.popen.poll() is None and time.monotonic() < deadline:
        rss.append(node.rss_mb())
        time.sleep(0.5)
    played = json.loads(player.wait(10))
    out = json.loads(node.stop())
    inputs = sum(played["messages"].values())
    assert inputs >= 0.8 * 3 * 100 * seconds  # three topics at 100 Hz each
    # Advice keeps coming at its rate (1 Hz of stamp time = wall time here).
    assert out["advice_published"] >= 0.6 * seconds
    # Memory stays flat: what the second half adds is noise, not a leak.
    half = len(rss) // 2
    assert max(rss[half:]) - rss[half] < 15, rss
    print(f"flood {seconds:g} s: {inputs} inputs, {out['advice_published']} advice, "
          f"RSS {rss[0]:.0f} -> {rss[half]:.0f} -> {rss[-1]:.0f} MB")


def test_flood_of_100hz_inputs_10s(tmp_path: Path, tmp_path_factory: pytest.TempPathFactory
                                   ) -> None:
    _flood(cached_ride(tmp_path_factory.getbasetemp(), input_hz=100, gps_hz=100,
                       duration_s=12), tmp_path, 10)


@pytest.mark.slow
def test_flood_of_100hz_inputs_60s(tmp_path: Path, tmp_path_factory: pytest.TempPathFactory
                                   ) -> None:
    _flood(cached_ride(tmp_path_factory.getbasetemp(), input_hz=100, gps_hz=100,
                       duration_s=65), tmp_path, 60)
