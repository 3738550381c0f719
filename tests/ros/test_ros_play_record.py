"""`play` and `record` on real rclpy (Fast DDS), across processes on this host.

A player process publishes the demo bag with `/clock`; a recorder process records every
topic (`-a`) on the ROS time of that clock until SIGINT. The recorded log must hold the
same messages (the same bytes, but for Fast DDS's padding), which every reader (mcap,
mcap_ros2, rosbags, Rerun) decodes to its declared type, with the QoS the player offered.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy", reason="real ROS 2 (rclpy) is not installed here")
pytest.importorskip("itt_msgs.msg", reason="the itt_msgs interfaces are not built here")

from itt_planner_ros.player import PlaySettings, play  # noqa: E402
from itt_planner_ros.ros_types import (  # noqa: E402
    edge_node,
    offers_yaml,
    replay_qos,
)
from mcap.reader import make_reader  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rosbags.rosbag2.metadata import parse_qos  # noqa: E402
from support.mcap_readers import check_all_readers, raw_counts, rosbags_messages  # noqa: E402

from itt_msgs_py import topics  # noqa: E402
from itt_msgs_py.qos import OFFERED_QOS_KEY, offered_qos_yaml  # noqa: E402
from itt_planner.errors import RideLogError  # noqa: E402
from itt_planner.logs.ridelog import RideLogReader, message_count  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
DEMO_BAG = ROOT / "bags" / "typical_verona-like.mcap"
#: 1338 s of ride in ~6.7 s.
RATE = 200.0

RECORD = """
import json, signal, sys, threading
from itt_planner_ros.recorder import RecordSettings, record
stop = threading.Event()
for sig in (signal.SIGINT, signal.SIGTERM):
    signal.signal(sig, lambda *_: stop.set())
settings = RecordSettings(topics=tuple(sys.argv[2:]), all_topics=not sys.argv[2:],
                          use_sim_time=True)
print('recording', flush=True)
stats = record(sys.argv[1], settings, stop)
print(json.dumps(stats.as_dict()))
"""

PLAY = """
import json, sys
from itt_planner_ros.player import PlaySettings, play
stats = play(sys.argv[1], PlaySettings(rate=float(sys.argv[2]), clock_hz=40.0,
                                       wait_for_matched_s=30.0))
print(json.dumps(stats.as_dict()))
"""


def _python(script: str, *args: str, env: dict[str, str]) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-c", script, *args], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _start_recorder(output: Path, *topic_names: str,
                    env: dict[str, str]) -> subprocess.Popen[str]:
    proc = _python(RECORD, str(output), *topic_names, env=env)
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "recording", proc.stderr.read()  # type: ignore[union-attr]
    return proc


def _stop(proc: subprocess.Popen[str], sig: signal.Signals) -> dict[str, Any]:
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)  # a loaded machine tears down slowly
    assert proc.returncode == 0, err
    sys.stderr.write(err)  # shown with a failure
    stats: dict[str, Any] = json.loads(out.strip().splitlines()[-1])
    return stats


def _payloads(path: Path) -> dict[str, list[bytes]]:
    out: dict[str, list[bytes]] = {}
    for record in RideLogReader(path).records():
        out.setdefault(record.topic, []).append(record.data)
    return out


def _missing(got: list[bytes], given: list[bytes]) -> str:
    """Which of the given messages (in order) were not received, for a failure."""
    lost, j = [], 0
    for i, data in enumerate(given):
        if j < len(got) and got[j][:len(data)] == data:
            j += 1
        else:
            lost.append(i)
    return f"lost messages at indexes {lost} of {len(given)}"


def _offers(path: Path) -> dict[str, str]:
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return {c.topic: c.metadata[OFFERED_QOS_KEY] for c in summary.channels.values()}


def test_play_clock_and_record_all_across_processes(tmp_path: Path,
                                                    ros_env: dict[str, str]) -> None:
    output = tmp_path / "recorded.mcap"
    recorder = _start_recorder(output, env=ros_env)
    player = _python(PLAY, str(DEMO_BAG), str(RATE), env=ros_env)
    out, err = player.communicate(timeout=120)
    assert player.returncode == 0, err
    played = json.loads(out.strip().splitlines()[-1])
    time.sleep(2.0)  # the last messages are in flight (a loaded machine delays them)
    recorded = _stop(recorder, signal.SIGINT)

    given = raw_counts(DEMO_BAG)
    assert set(given) == {"/itt/gps/fix", "/itt/speed", "/itt/power"}
    assert played["messages"] == {t: n for t, (_, n) in given.items()}
    assert not played["unplayable"] and not played["refused"] and not played["unmatched"]
    # Every message, in order, on its topic (loopback: nothing lost), byte for byte but
    # for the zeros Fast DDS pads a payload with to a multiple of 4 bytes.
    got = raw_counts(output)
    payloads = _payloads(output)
    for topic_name, (msgtype, n) in given.items():
        assert got[topic_name] == (msgtype, n), _missing(payloads[topic_name],
                                                         _payloads(DEMO_BAG)[topic_name])
    for topic_name, data in _payloads(DEMO_BAG).items():
        assert [p[:len(d)] for p, d in zip(payloads[topic_name], data, strict=True)] == data
        assert all(p[len(d):] == bytes(len(p) - len(d)) and len(p) % 4 == 0
                   for p, d in zip(payloads[topic_name], data, strict=True))
    assert recorded["messages"] == {t: n for t, (_, n) in got.items()}
    assert not recorded["skipped"]
    # /clock was played and recorded, and the log times are ROS time from it.
    assert got["/clock"][0] == "rosgraph_msgs/msg/Clock"
    ride_s = 1338.0  # 40 Hz of wall time while playing, more while waiting for matches
    assert ride_s / RATE * 40 * 0.5 <= got["/clock"][1] <= played["clock_messages"]
    # Only the player node's parameter events can come before its first /clock.
    assert recorded["wall_clock_stamped"] <= got.get("/parameter_events", ("", 0))[1]
    ride = [r.log_time_ns for r in RideLogReader(DEMO_BAG).records()]
    times = [r.log_time_ns for r in RideLogReader(output).records() if r.topic in given]
    assert min(ride) <= min(times) and max(times) <= max(ride) + 2_000_000_000
    # mcap, mcap_ros2, rosbags and Rerun read the same topics, types and counts.
    check_all_readers(output, got, tmp_path)
    info, decoded = rosbags_messages(output)
    for topic_name, messages in decoded.items():
        assert {m.__msgtype__ for m in messages} == {info[topic_name][0]}
    # QoS as offered: the player offered the log's (best effort, volatile).
    recorded_qos, given_qos = _offers(output), _offers(DEMO_BAG)
    for topic_name in given:
        (offer,), (source,) = parse_qos(recorded_qos[topic_name]), parse_qos(given_qos[topic_name])
        assert (offer.reliability, offer.durability) == (source.reliability, source.durability)
    assert "best_effort" in recorded_qos["/clock"]


def test_record_named_topic_finishes_on_sigterm(tmp_path: Path,
                                                ros_env: dict[str, str]) -> None:
    """An rclpy publisher, reliable and latched: the recorder asks for the same."""
    from sensor_msgs.msg import NavSatFix

    output = tmp_path / "fix.mcap"
    recorder = _start_recorder(output, "/itt/gps/fix", env=ros_env)
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
    with edge_node("plain_publisher") as node:
        fix = node.create_publisher(NavSatFix, "/itt/gps/fix", qos)
        other = node.create_publisher(NavSatFix, "/not_recorded", qos)
        deadline = time.monotonic() + 30
        while fix.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert fix.get_subscription_count() == 1
        for i in range(50):
            fix.publish(NavSatFix(latitude=45.0 + i * 1e-5))
            other.publish(NavSatFix())
        time.sleep(0.3)
        recorded = _stop(recorder, signal.SIGTERM)
    assert recorded["messages"] == {"/itt/gps/fix": 50}
    assert message_count(output) == 50  # the summary was written: the file is finished
    _, decoded = rosbags_messages(output)
    assert [m.latitude for m in decoded["/itt/gps/fix"]] == [45.0 + i * 1e-5 for i in range(50)]
    (offer,) = parse_qos(_offers(output)["/itt/gps/fix"])
    assert (offer.reliability.name, offer.durability.name) == ("RELIABLE", "TRANSIENT_LOCAL")


@pytest.mark.usefixtures("ros_env")
def test_play_topics_offset_and_stop() -> None:
    """Only the chosen topic, from the offset on; a looping player stops on the event."""
    from sensor_msgs.msg import NavSatFix

    received: list[float] = []
    context = Context()
    rclpy.init(context=context)
    try:
        with edge_node("listener", context) as node:
            def on_fix(msg: Any) -> None:
                received.append(msg.latitude)

            # Deep enough that a busy machine's late executor turn loses nothing.
            node.create_subscription(NavSatFix, "/itt/gps/fix", on_fix,
                                     QoSProfile(depth=100,
                                                reliability=ReliabilityPolicy.BEST_EFFORT))
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(node)
            spinner = threading.Thread(target=executor.spin, daemon=True)
            spinner.start()
            settings = PlaySettings(rate=RATE, start_offset_s=1300.0, wait_for_matched_s=30,
                                    topics=("/itt/gps/fix",))
            stats = play(DEMO_BAG, settings)
            time.sleep(0.3)
            received_from_offset = len(received)
            stop = threading.Event()
            threading.Timer(1.5, stop.set).start()
            started = time.monotonic()
            # At rate 0.1 the second fix is due 10 s in: the stop comes while waiting.
            looped = play(DEMO_BAG, PlaySettings(rate=0.1, loop=True,
                                                 topics=("/itt/gps/fix",)), stop)
            stopped_after_s = time.monotonic() - started
            executor.shutdown()
    finally:
        context.try_shutdown()
    fixes = [r.log_time_ns for r in RideLogReader(DEMO_BAG).records()
             if r.topic == "/itt/gps/fix"]
    expected = sum(t >= fixes[0] + 1300 * 10**9 for t in fixes)
    assert expected == 38  # log times 1300..1337 s (the bag remade 2026-12-02)
    assert stats.messages == Counter({"/itt/gps/fix": expected})
    assert received_from_offset == expected
    assert stopped_after_s < 3.0 and looped.loops == 0 and looped.messages.total() <= 1


@pytest.mark.usefixtures("ros_env")
def test_play_delay_holds_all_but_the_start_clock() -> None:
    """During `delay_s` only `/clock` goes out, at the start time (the log's first time plus
    the offset); a stop then ends the play before any message. A negative delay is refused."""
    from rosgraph_msgs.msg import Clock

    with pytest.raises(RideLogError, match="delay must be >= 0"):
        play(DEMO_BAG, PlaySettings(delay_s=-1.0))
    first = next(RideLogReader(DEMO_BAG).records()).log_time_ns
    clocks: list[int] = []
    stop = threading.Event()
    context = Context()
    rclpy.init(context=context)
    try:
        with edge_node("listener", context) as node:
            def on_clock(msg: Any) -> None:
                clocks.append(msg.clock.sec * 10**9 + msg.clock.nanosec)
                if len(clocks) >= 5:
                    stop.set()

            node.create_subscription(Clock, "/clock", on_clock, QoSProfile(
                depth=100, reliability=ReliabilityPolicy.BEST_EFFORT))
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(node)
            threading.Thread(target=executor.spin, daemon=True).start()
            threading.Timer(60.0, stop.set).start()  # a safety net, not a bound
            # In this context, so no discovery: the listener matches as the player starts.
            stats = play(DEMO_BAG, PlaySettings(rate=RATE, clock_hz=40.0, start_offset_s=1300,
                                                delay_s=3600.0), stop, context=context)
            executor.shutdown()
    finally:
        context.try_shutdown()
    assert len(clocks) >= 5 and set(clocks) == {first + 1300 * 10**9}
    assert stats.messages.total() == 0 and stats.clock_messages >= 5


def test_qos_round_trip_as_rosbag2() -> None:
    """Offers recorded from the graph read back as the profile `ros2 bag play` offers."""
    graph_offer = QoSProfile(depth=0, history=HistoryPolicy.UNKNOWN,
                             reliability=ReliabilityPolicy.BEST_EFFORT,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
    replayed = replay_qos(offers_yaml([graph_offer]))
    assert replayed.reliability is ReliabilityPolicy.BEST_EFFORT
    assert replayed.durability is DurabilityPolicy.TRANSIENT_LOCAL
    assert (replayed.history, replayed.depth) == (HistoryPolicy.KEEP_LAST, 10)
    reliable = QoSProfile(depth=7, reliability=ReliabilityPolicy.RELIABLE)
    mixed = replay_qos(offers_yaml([graph_offer, reliable]))  # disagree: ROS default
    assert mixed.reliability is ReliabilityPolicy.RELIABLE
    assert mixed.durability is DurabilityPolicy.VOLATILE and mixed.depth == 7
    # The interface's own logs (ridelog) and a log without offers.
    assert replay_qos(offered_qos_yaml(topics.SENSOR_QOS)).reliability \
        is ReliabilityPolicy.BEST_EFFORT
    assert replay_qos("", topics.SENSOR_QOS).depth == topics.SENSOR_QOS.depth
