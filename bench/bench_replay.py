"""Benchmark of the embedded replay: a ~24-minute ride with 1 Hz replanning.

Runs `itt_planner.session.replay.replay_ride`, exactly what `itt-planner replay --speed max` runs
(deterministic planner: IPOPT's iteration cap is the budget, no wall-time cap), on the
`make demo` bag `bags/typical_verona-like_cp-overestimated.mcap` (a simulated 23-minute
ride whose real CP is 5 % below the belief: GPS 1 Hz with 3 m noise, speed and power
noise). Prints medians of >= 3 runs of:

- full:       replay with the engine advising every 1 s of stamp time (the plan while
              the rider is on it, then a horizon solve every second after the CP refit),
              output MCAP written;
- estimate:   the same engine and log, replanning disabled (one advice, then estimation
              only): the cost of everything but the horizon solves;
- decode:     reading and decoding the log only (the floor of any replay).

Usage: .venv/bin/python bench/bench_replay.py [--runs 3] [--model 1d|3d]
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from itt_planner.course.loader import load_course  # noqa: E402
from itt_planner.logs.ridelog import RideLogReader  # noqa: E402
from itt_planner.model.conditions import Conditions  # noqa: E402
from itt_planner.model.rider import PRESETS  # noqa: E402
from itt_planner.ocp.cache import load_or_solve  # noqa: E402
from itt_planner.ocp.course_settings import OcpSettings  # noqa: E402
from itt_planner.session.config import SessionConfig  # noqa: E402
from itt_planner.session.replay import ReplayResult, replay_ride  # noqa: E402

T = TypeVar("T")
COURSE = "verona-like"
RIDER = "typical"
DEMO_BAG = ROOT / "bags" / "typical_verona-like_cp-overestimated.mcap"


def median_of(runs: int, fn: Callable[[], T]) -> tuple[float, list[float], T]:
    """Median wall time of `runs` calls, every time, and the last call's result."""
    times: list[float] = []
    for _ in range(runs):
        t0 = time.perf_counter()
        last = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), times, last


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--model", default="3d", choices=("1d", "3d"))
    args = parser.parse_args()

    course = load_course(COURSE)
    rider = PRESETS[RIDER]
    conditions = Conditions()
    t0 = time.perf_counter()
    plan = load_or_solve(course, rider, conditions, OcpSettings(), args.model,
                         cache_dir=ROOT / ".itt_cache")
    print(f"full-course plan ({args.model}): {time.perf_counter() - t0:.1f} s "
          f"(cached after the first run), finish {plan.finish_time_s / 60:.1f} min")

    with tempfile.TemporaryDirectory() as tmp:
        tmp_dir = Path(tmp)
        log_path = DEMO_BAG
        print(f"input: {log_path.relative_to(ROOT)}")

        def run(replan_period_s: float) -> ReplayResult:
            config = SessionConfig(course=COURSE, rider=RIDER, model=args.model,
                                   replan_period_s=replan_period_s, deterministic=True,
                                   plan_cache=str(ROOT / ".itt_cache"))
            return replay_ride(log_path, config, output=tmp_dir / "advice.mcap",
                               progress=True)

        full_s, full_all, full = median_of(args.runs, lambda: run(1.0))
        est_s, est_all, est = median_of(args.runs, lambda: run(math.inf))
        dec_s, dec_all, _ = median_of(args.runs, lambda: sum(1 for _ in RideLogReader(log_path)))

    ride_s = full.ride_duration_s
    solve = sorted(full.solve_times_s)
    print(f"ride: {ride_s / 60:.1f} min of stamps, {full.messages_in} input messages, "
          f"{full.advice_out} advice ({full.fallbacks} fallbacks)")
    rows: tuple[tuple[str, float, list[float], ReplayResult | None], ...] = (
        ("full (1 Hz replans)", full_s, full_all, full), ("estimate only", est_s, est_all, est),
        ("decode only", dec_s, dec_all, None))
    for name, med, all_, result in rows:
        extra = f", {result.advice_out} advice" if result is not None else ""
        print(f"{name:22s} median {med:7.2f} s  ({', '.join(f'{t:.2f}' for t in all_)})  "
              f"{ride_s / med:7.1f}x real time{extra}")
    print(f"horizon solves: median {solve[len(solve) // 2] * 1000:.1f} ms, "
          f"p95 {solve[int(0.95 * (len(solve) - 1))] * 1000:.1f} ms, "
          f"max {solve[-1] * 1000:.1f} ms over {len(solve)} solves")
    print(f"ratios: full / estimate-only = {full_s / est_s:.1f}, "
          f"full / decode-only = {full_s / dec_s:.1f}; "
          f"solves take {sum(solve) / full.wall_time_s * 100:.0f} % of the last full run")
    return 0


if __name__ == "__main__":
    sys.exit(main())
