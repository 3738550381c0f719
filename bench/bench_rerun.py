"""Benchmark of a full demo-ride Rerun recording: file size and logging time.

A ~21-minute ride on the verona-like demo course (16.8 km) with the synthetic plan and
ride of tests/support/synthetic_ride.py (the OCP and the engine are not needed to measure the
recorder): power and wheel speed at RATE Hz, GPS fix, rider state, advice (1000 m horizon)
and diagnostics at 1 Hz. Prints medians of >= 3 runs of:

- full:    RideRecorder -> file:ride.rrd (the review recording); size of the .rrd;
- static:  log_course() only (course, road mesh, plan curves): the fixed part of the size;
- memory:  the full ride into an in-memory recording (no file): the logging cost alone,
           the baseline of the time ratio.

Usage: .venv/bin/python bench/bench_rerun.py [--runs 3] [--rate 4]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))  # the synthetic ride is shared with the tests

import rerun as rr  # noqa: E402
from support.rerun_feed import Event, record  # noqa: E402
from support.synthetic_ride import RIDER, make_plan, make_ride  # noqa: E402

from itt_planner.course.geometry import Course  # noqa: E402
from itt_planner.course.loader import load_course  # noqa: E402
from itt_planner.ocp.plan import Plan  # noqa: E402
from itt_planner.view.rerun_log import RideRecorder  # noqa: E402
from itt_planner.view.rerun_sink import RerunSink, open_recording  # noqa: E402

LIMIT_BYTES = 50 * 1024 * 1024


def run(sink: str, events: list[Event] | None, course: Course, plan: Plan) -> float:
    start = time.perf_counter()
    if sink == "memory":
        rec = rr.RecordingStream("itt_planner")
        rec.memory_recording()
    else:
        rec = open_recording(RerunSink.parse(sink))
    recorder = RideRecorder(rec, course, RIDER, plan)
    recorder.log_course()
    if events is not None:
        record(recorder, events)
    rec.flush()
    rec.disconnect()
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--rate", type=float, default=4.0, help="power/speed rate (Hz)")
    args = parser.parse_args()
    course = load_course("verona-like")
    plan = make_plan(course)
    events = make_ride(course, plan, rate_hz=args.rate)
    print(f"course {course.name} {course.length_m / 1000:.1f} km, ride "
          f"{plan.finish_time_s / 60:.1f} min, {len(events)} events, plan {plan.n_nodes} nodes")
    with tempfile.TemporaryDirectory() as tmp:
        full_rrd, static_rrd = Path(tmp) / "full.rrd", Path(tmp) / "static.rrd"
        times = {
            "full": [run(f"file:{full_rrd}", events, course, plan) for _ in range(args.runs)],
            "static": [run(f"file:{static_rrd}", None, course, plan) for _ in range(args.runs)],
            "memory": [run("memory", events, course, plan) for _ in range(args.runs)],
        }
        sizes = {"full": full_rrd.stat().st_size, "static": static_rrd.stat().st_size}
    med = {k: statistics.median(v) for k, v in times.items()}
    for name, seconds in med.items():
        size = f", {sizes[name] / 1e6:6.2f} MB" if name in sizes else ""
        print(f"{name:7s} median {seconds:6.2f} s over {args.runs} runs{size}")
    print(f"full / memory time ratio {med['full'] / med['memory']:.2f}; "
          f"full / static size ratio {sizes['full'] / sizes['static']:.2f}; "
          f"{sizes['full'] / (plan.finish_time_s / 3600) / 1e6:.1f} MB per ride hour; "
          f"limit 50 MB: {'OK' if sizes['full'] <= LIMIT_BYTES else 'EXCEEDED'}")


if __name__ == "__main__":
    main()
