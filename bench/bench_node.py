"""End-to-end latency of the pacing node on real rclpy: GPS fix published -> advice.

`python -m bench.bench_node [--runs 3] [--seconds 30]`

Each run starts `itt-planner node` (real rclpy, Fast DDS confined to loopback by the
shipped profile, a domain of its own) on the hairpin test course and publishes a ride at
10 Hz (GPS fix, wheel speed and power each at 10 Hz, stamps on the ride clock, paced in
real time); the node replans at 1 Hz of stamp time. An advice carries the stamp of the
newest input at its replan, i.e. of the GPS fix published at that instant: its latency is
the wall time from that fix's publication to the advice's arrival (tick wait + horizon
solve + DDS both ways). Every advice is a horizon solve (`on_plan_band_j:=0.0`).

Baseline, measured in the same run: the rclpy publish -> subscribe echo round trip
across two processes (`bench.bench_ros_echo`), the transport cost the node's latency
contains twice.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import statistics
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from itt_planner_ros.ros_types import edge_node, message_class, qos_profile
from rclpy.executors import SingleThreadedExecutor
from support.ros_support import RIDE_T0_S, RIDER, Proc, Ride, cli, make_ride

from bench.bench_ros_echo import echo_round_trips_ms
from itt_msgs_py import deserialize, registry, serialize, topics
from itt_msgs_py.convert import from_time
from itt_msgs_py.dds_env import localhost_env
from itt_planner.logs.ridelog import read_ride_log


def node_latency_ms(ride: Ride, folder: Path, seconds: float, env: dict[str, str]
                    ) -> tuple[list[float], list[float], int]:
    """Latencies (ms) of the advice of one node run, their solve times (ms), and the
    number of GPS fixes sent."""
    folder.mkdir(parents=True, exist_ok=True)
    # on_plan_band_j 0: every advice is a horizon solve (the rider here follows the plan,
    # so with the default band the advice would be the plan itself, no solve).
    node = Proc(cli("node", "--course", str(ride.course), "--rider", RIDER, "--plan",
                    str(ride.plan), "--json",
                    "--ros-args", "-p", "on_plan_band_j:=0.0"), env, folder / "node.log")
    arrivals: list[tuple[float, bytes]] = []
    sent: dict[float, float] = {}  # GPS stamp -> wall time published
    try:
        node.wait_for("ready on /itt", 120)
        with edge_node("bench_node") as bench:
            pubs = {t.key: bench.create_publisher(message_class(t.msgtype), t.name(),
                                                  qos_profile(t.qos))
                    for t in registry.INPUT_TOPICS}
            def on_advice(data: Any) -> None:  # raw=True: the CDR bytes
                arrivals.append((time.perf_counter(), data))

            bench.create_subscription(message_class(topics.ADVICE.msgtype),
                                      topics.ADVICE.name(), on_advice,
                                      qos_profile(topics.ADVICE.qos), raw=True)
            executor = SingleThreadedExecutor(context=bench.context)
            executor.add_node(bench)
            spinner = threading.Thread(target=executor.spin, daemon=True)
            spinner.start()
            deadline = time.monotonic() + 30
            while not all(p.get_subscription_count() for p in pubs.values()):
                if time.monotonic() > deadline:
                    raise RuntimeError("the node's subscriptions did not match")
                time.sleep(0.05)
            start = time.perf_counter()
            for _topic, stamp, sample in read_ride_log(ride.log):
                if stamp - RIDE_T0_S > seconds:
                    break
                time.sleep(max(0.0, start + (stamp - RIDE_T0_S) - time.perf_counter()))
                assert registry.is_sample(sample)
                topic, sample_msg = registry.sample_to_msg(sample)
                pubs[topic.key].publish(serialize(sample_msg))
                if topic is registry.GPS_FIX:
                    sent[round(stamp, 3)] = time.perf_counter()
            time.sleep(2.0)
            executor.shutdown()
            spinner.join(5)
    finally:
        node.stop()
    latencies: list[float] = []
    solves: list[float] = []
    for arrived, data in arrivals:
        msg: Any = deserialize(data, topics.ADVICE.msgtype)  # an itt_msgs/Advice
        stamp = round(from_time(msg.header.stamp), 3)
        if stamp in sent:
            latencies.append((arrived - sent[stamp]) * 1e3)
            solves.append(msg.solve_time_s * 1e3)
    return latencies, solves, len(sent)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=30.0, help="ride time per run")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="bench_node_"))
    ride = make_ride(folder / "ride", input_hz=10, gps_hz=10, duration_s=args.seconds + 5)
    os.environ.update(localhost_env(random.randint(1, 101)))
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    rows = []
    for run in range(args.runs):
        rtt = echo_round_trips_ms(env, folder / f"echo{run}.log")
        lat, solves, fixes = node_latency_ms(ride, folder / f"run{run}", args.seconds, env)
        row = {"run": run, "fixes": fixes, "advice": len(lat),
               "node_median_ms": statistics.median(lat),
               "node_p95_ms": float(np.percentile(lat, 95)),
               "solve_median_ms": statistics.median(solves),
               "echo_median_ms": statistics.median(rtt),
               "echo_p95_ms": float(np.percentile(rtt, 95))}
        rows.append(row)
        print(json.dumps(row), flush=True)
    med = {k: statistics.median(r[k] for r in rows) for k in rows[0] if k.endswith("_ms")}
    print(f"median of {args.runs} runs: node GPS->advice median {med['node_median_ms']:.1f} ms, "
          f"p95 {med['node_p95_ms']:.1f} ms; rclpy echo round trip median "
          f"{med['echo_median_ms']:.2f} ms, p95 {med['echo_p95_ms']:.2f} ms; ratio node/echo "
          f"(medians) {med['node_median_ms'] / med['echo_median_ms']:.0f}x; horizon solve "
          f"median {med['solve_median_ms']:.0f} ms, so the node adds "
          f"{med['node_median_ms'] - med['solve_median_ms']:.0f} ms around the solve")


if __name__ == "__main__":
    main()
