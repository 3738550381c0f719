"""rclpy publish -> subscribe echo across two processes: the floor of the node's latency.

`python bench/bench_ros_echo.py [--runs 3] [--round-trips 200] [--period 0.05]`

A second process (real rclpy, Fast DDS confined to loopback by the shipped profile, a
domain of its own) subscribes to `/bench/ping` as the node subscribes to a GPS fix (raw
CDR, sensor-data QoS: best effort, keep last 5) and republishes each payload on
`/bench/pong` as the node publishes advice (reliable, keep last 10). This process
publishes a `sensor_msgs/NavSatFix` (the demo ride's: 125 bytes of CDR), one at
a time every `period` s (the node's inputs come at 10 Hz, so both processes sleep between
messages, as the node's do), and takes the echo in its executor: a round trip is two
rclpy hops, which the node's GPS fix -> advice latency (`bench/bench_node.py`) contains.

Baseline, measured in the same run: the same payload echoed over a plain UDP socket on
127.0.0.1 by the same second process, the operating system's floor.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

PING = "/bench/ping"
PONG = "/bench/pong"
#: The variables that must agree between this process and the echo process.
ROS_VARS = ("ROS_DOMAIN_ID", "FASTRTPS_DEFAULT_PROFILES_FILE", "RMW_IMPLEMENTATION")
#: A round trip not back by then is counted as lost.
TIMEOUT_S = 1.0
#: Round trips before the measured ones (discovery settling, caches).
WARM_UP = 20


# rclpy and the message packages are imported where used: the echo process and this one
# set their ROS environment (domain, loopback-only profile) first.


def _fix() -> Any:
    """A GPS fix like the demo ride's (frame `gps`, a fix, diagonal covariance)."""
    from sensor_msgs.msg import NavSatFix, NavSatStatus  # noqa: PLC0415

    fix = NavSatFix(latitude=45.438, longitude=10.992, altitude=60.0,
                    position_covariance_type=NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN)
    fix.header.frame_id = "gps"
    fix.status.status = NavSatStatus.STATUS_FIX
    fix.position_covariance = [9.0, 0.0, 0.0, 0.0, 9.0, 0.0, 0.0, 0.0, 20.0]
    return fix


def serve_echo() -> None:
    """The echo process: rclpy ping -> pong, and a UDP echo; until SIGTERM/SIGINT."""
    from itt_planner_ros.ros_types import edge_node  # noqa: PLC0415
    from rclpy.executors import SingleThreadedExecutor  # noqa: PLC0415
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data  # noqa: PLC0415
    from sensor_msgs.msg import NavSatFix  # noqa: PLC0415

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", 0))
    udp.settimeout(0.1)

    def udp_echo() -> None:
        while not stop.is_set():
            try:
                data, peer = udp.recvfrom(65536)
            except TimeoutError:
                continue
            udp.sendto(data, peer)

    threading.Thread(target=udp_echo, daemon=True).start()
    with edge_node("bench_echo") as node:
        pong = node.create_publisher(NavSatFix, PONG, QoSProfile(
            depth=10, reliability=ReliabilityPolicy.RELIABLE))
        node.create_subscription(NavSatFix, PING, pong.publish, qos_profile_sensor_data,
                                 raw=True)
        executor = SingleThreadedExecutor(context=node.context)
        executor.add_node(node)
        print(f"ready udp {udp.getsockname()[1]}", flush=True)
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.1)
        executor.shutdown()


def _udp_round_trips_ms(port: int, payload: bytes, count: int, period_s: float) -> list[float]:
    rtts = []
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.settimeout(TIMEOUT_S)
        for i in range(WARM_UP + count):
            sent = time.perf_counter()
            sock.sendto(payload, ("127.0.0.1", port))
            sock.recvfrom(65536)
            if i >= WARM_UP:
                rtts.append((time.perf_counter() - sent) * 1e3)
            time.sleep(period_s)
    return rtts


def echo_round_trips_ms(  # noqa: PLR0912, PLR0915  (one measurement: start, match, time, stop)
        env: dict[str, str], log: Path, count: int = 200, period_s: float = 0.05,
        udp: list[float] | None = None) -> list[float]:
    """Round-trip times (ms) of `count` rclpy echoes through a second process.

    `env` is the echo process's environment; this process must already hold the same ROS
    variables (`ROS_VARS`), as its rclpy context reads them from `os.environ`. The echo
    process's stderr goes to `log`. With `udp` given, the UDP baseline's round trips are
    appended to it.

    Raises:
        RuntimeError: the echo process did not start, the topics did not match, or more
            than 5 % of the round trips were lost.
    """
    from itt_planner_ros.ros_types import edge_node  # noqa: PLC0415
    from rclpy.executors import SingleThreadedExecutor  # noqa: PLC0415
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data  # noqa: PLC0415
    from rclpy.serialization import serialize_message  # noqa: PLC0415
    from sensor_msgs.msg import NavSatFix  # noqa: PLC0415

    differ = [k for k in ROS_VARS if env.get(k) != os.environ.get(k)]
    if differ:
        raise RuntimeError(f"echo benchmark: {differ} differ between env and os.environ")
    with log.open("wb") as err:
        proc = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--echo"],
                                env=env, stdout=subprocess.PIPE, stderr=err, text=True)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline().split()
        if line[:2] != ["ready", "udp"]:
            raise RuntimeError(f"the echo process did not start: see {log}")
        fix = _fix()
        if udp is not None:
            udp.extend(_udp_round_trips_ms(int(line[2]), serialize_message(fix), count,
                                           period_s))
        arrived: list[tuple[float, Any]] = []  # raw: the CDR bytes
        with edge_node("bench_ping") as node:
            ping = node.create_publisher(NavSatFix, PING, qos_profile_sensor_data)
            pong = node.create_subscription(
                NavSatFix, PONG, lambda data: arrived.append((time.perf_counter(), data)),
                QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE), raw=True)
            executor = SingleThreadedExecutor(context=node.context)
            executor.add_node(node)
            deadline = time.monotonic() + 30
            while ping.get_subscription_count() == 0 or pong.get_publisher_count() == 0:
                if time.monotonic() > deadline:
                    raise RuntimeError("echo benchmark: the topics did not match in 30 s")
                time.sleep(0.02)
            rtts, lost = [], 0
            for i in range(WARM_UP + count):
                fix.header.stamp.sec = i  # which ping a pong answers
                expected = serialize_message(fix)
                arrived.clear()
                sent = time.perf_counter()
                ping.publish(fix)
                while not arrived and time.perf_counter() - sent < TIMEOUT_S:
                    executor.spin_once(timeout_sec=TIMEOUT_S)
                # The echo may be Fast DDS-padded to 4 bytes: compare the message's bytes.
                answered = [t for t, data in arrived if data[:len(expected)] == expected]
                if i >= WARM_UP:
                    if answered:
                        rtts.append((answered[0] - sent) * 1e3)
                    else:
                        lost += 1
                time.sleep(period_s)
            executor.shutdown()
        if lost > 0.05 * count:
            raise RuntimeError(f"echo benchmark: {lost} of {count} round trips lost")
        return rtts
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--round-trips", type=int, default=200)
    parser.add_argument("--period", type=float, default=0.05, help="s between pings")
    parser.add_argument("--echo", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.echo:
        serve_echo()
        return
    from itt_msgs_py.dds_env import CONFLICTING_VARS, localhost_env  # noqa: PLC0415

    for var in CONFLICTING_VARS:
        os.environ.pop(var, None)
    os.environ.update(localhost_env(random.randint(1, 101)))
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    folder = Path(tempfile.mkdtemp(prefix="bench_ros_echo_"))
    rows = []
    for run in range(args.runs):
        udp: list[float] = []
        rtts = echo_round_trips_ms(env, folder / f"echo{run}.log", args.round_trips,
                                   args.period, udp)
        row = {"run": run, "round_trips": len(rtts),
               "rclpy_median_ms": statistics.median(rtts),
               "rclpy_p95_ms": float(np.percentile(rtts, 95)),
               "udp_median_ms": statistics.median(udp),
               "udp_p95_ms": float(np.percentile(udp, 95))}
        rows.append(row)
        print(json.dumps(row), flush=True)
    med = {k: statistics.median(r[k] for r in rows) for k in rows[0] if k.endswith("_ms")}
    print(f"median of {args.runs} runs ({args.round_trips} round trips each, one every "
          f"{args.period * 1e3:.0f} ms): rclpy echo round trip median "
          f"{med['rclpy_median_ms']:.3f} ms, p95 {med['rclpy_p95_ms']:.3f} ms; UDP echo "
          f"median {med['udp_median_ms']:.3f} ms, p95 {med['udp_p95_ms']:.3f} ms; ratio "
          f"rclpy/UDP (medians) {med['rclpy_median_ms'] / med['udp_median_ms']:.1f}x")


if __name__ == "__main__":
    main()
