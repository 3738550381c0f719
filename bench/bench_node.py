"""End-to-end latency of the pacing node on the DDS layer: GPS fix published -> advice.

`python bench/bench_node.py [--runs 3] [--seconds 30]`

Each run starts `itt-planner node` (DDS layer, loopback Cyclone config, a domain of its
own) on the hairpin test course and publishes a ride at 10 Hz (GPS fix, wheel speed and
power each at 10 Hz, stamps on the ride clock, paced in real time); the node replans at
1 Hz of stamp time. An advice carries the stamp of the newest input at its replan, i.e.
of the GPS fix published at that instant: its latency is the wall time from that fix's
publication to the advice's arrival (tick wait + horizon solve + DDS both ways).

Baseline, measured in the same run: a raw DDS echo round trip on the same machine (a
second process republishes each NavSatFix payload it receives; latency from publishing
to receiving the echo), the transport cost the node's latency contains twice.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the test ride of the DDS tests (dds_support)

from dds_support import RIDE_T0_S, Proc, Ride, cli, dds_env, make_ride

from itt_msgs_py import deserialize, serialize, topics
from itt_msgs_py.convert import from_time, sample_to_msg
from itt_planner.dds.context import Context
from itt_planner.dds.endpoints import RawReader, RawWriter
from itt_planner.ridelog import read_ride_log

FIX = "sensor_msgs/msg/NavSatFix"


def echo(domain: int) -> None:
    """The echo process: republish every /bench/ping payload on /bench/pong."""
    ctx = Context()
    ctx.init([], domain)
    pong = RawWriter(ctx.participant, "/bench/pong", FIX, topics.RELIABLE_QOS)
    ping: RawReader

    def on_data() -> None:
        for sample in ping.take():
            pong.write(sample.data)

    ping = RawReader(ctx.participant, "/bench/ping", FIX, topics.RELIABLE_QOS, on_data=on_data)
    print("echo ready", file=sys.stderr, flush=True)
    threading.Event().wait()


def _wait(predicate, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise RuntimeError("DDS endpoints did not match")
        time.sleep(0.02)


def echo_rtt_ms(ctx: Context, env: dict[str, str], ride: Ride, log: Path, n: int = 200
                ) -> list[float]:
    """Round trips of n NavSatFix payloads through the echo process (ms)."""
    proc = Proc([sys.executable, __file__, "--echo", env["ROS_DOMAIN_ID"]], env, log)
    try:
        proc.wait_for("echo ready", 30)
        ping = RawWriter(ctx.participant, "/bench/ping", FIX, topics.RELIABLE_QOS)
        got = threading.Event()
        pong = RawReader(ctx.participant, "/bench/pong", FIX, topics.RELIABLE_QOS,
                         on_data=got.set)
        _wait(lambda: ping.matched_count() and pong.matched_count(), 10)
        data = serialize(sample_to_msg(next(s for _t, _s, s in read_ride_log(ride.log)))[1])
        out = []
        for _ in range(n):
            got.clear()
            t0 = time.perf_counter()
            ping.write(data)
            got.wait(2)
            if pong.take():
                out.append((time.perf_counter() - t0) * 1e3)
            time.sleep(0.005)
        return out
    finally:
        proc.stop()


def node_latency_ms(ctx: Context, env: dict[str, str], ride: Ride, folder: Path,
                    seconds: float) -> tuple[list[float], list[float], int]:
    """Latencies (ms) of the advice of one node run, their solve times (ms), and the
    number of GPS fixes sent."""
    folder.mkdir(parents=True, exist_ok=True)
    node = Proc(cli("node", "--course", str(ride.course), "--plan", str(ride.plan),
                    "--json"), env, folder / "node.log")
    try:
        node.wait_for("ready on /itt", 120)
        writers = {t.key: RawWriter(ctx.participant, t.name(), t.msgtype, t.qos)
                   for t in topics.INPUT_TOPICS}
        arrivals: list[tuple[float, bytes]] = []
        advice: RawReader

        def on_advice() -> None:
            now = time.perf_counter()
            arrivals.extend((now, s.data) for s in advice.take())

        advice = RawReader(ctx.participant, topics.ADVICE.name(), topics.ADVICE.msgtype,
                           topics.ADVICE.qos, on_data=on_advice)
        _wait(lambda: all(w.matched_count() for w in writers.values())
              and advice.matched_count(), 30)
        sent: dict[float, float] = {}  # GPS stamp -> wall time published
        start = time.perf_counter()
        for _topic, stamp, sample in read_ride_log(ride.log):
            if stamp - RIDE_T0_S > seconds:
                break
            time.sleep(max(0.0, start + (stamp - RIDE_T0_S) - time.perf_counter()))
            topic, msg = sample_to_msg(sample)
            writers[topic.key].write(serialize(msg))
            if topic is topics.GPS_FIX:
                sent[round(stamp, 3)] = time.perf_counter()
        time.sleep(2.0)
    finally:
        node.stop()
    latencies, solves = [], []
    for arrived, data in arrivals:
        msg = deserialize(data, topics.ADVICE.msgtype)
        stamp = round(from_time(msg.header.stamp), 3)
        if stamp in sent:
            latencies.append((arrived - sent[stamp]) * 1e3)
            solves.append(msg.solve_time_s * 1e3)
    return latencies, solves, len(sent)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=30.0, help="ride time per run")
    parser.add_argument("--echo", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.echo is not None:
        echo(int(args.echo))
        return
    folder = Path(tempfile.mkdtemp(prefix="bench_node_"))
    ride = make_ride(folder / "ride", input_hz=10, gps_hz=10, duration_s=args.seconds + 5)
    env = dds_env()
    ctx = Context()
    ctx.init([], int(env["ROS_DOMAIN_ID"]))
    rows = []
    for run in range(args.runs):
        rtt = echo_rtt_ms(ctx, env, ride, folder / f"echo{run}.log")
        lat, solves, fixes = node_latency_ms(ctx, env, ride, folder / f"run{run}",
                                             args.seconds)
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
          f"p95 {med['node_p95_ms']:.1f} ms; DDS echo round trip median "
          f"{med['echo_median_ms']:.2f} ms, p95 {med['echo_p95_ms']:.2f} ms; ratio node/echo "
          f"(medians) {med['node_median_ms'] / med['echo_median_ms']:.0f}x; horizon solve "
          f"median {med['solve_median_ms']:.0f} ms, so the node adds "
          f"{med['node_median_ms'] - med['solve_median_ms']:.0f} ms around the solve")


if __name__ == "__main__":
    main()
