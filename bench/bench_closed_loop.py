"""Engine-level replan latency over a whole simulated verona-like race.

For horizons of 500 m and 1 km: one closed-loop race (`simulate_ride`, nominal, replan
every 1 s of ride time even on the plan, 1 Hz sensors) through the `PacingEngine`, recording every
replan's wall time (warm: the planner's shifted warm start, as live). Then every 10th
state of that race is re-solved cold (`HorizonPlanner.reset()` before each solve, so the
start is the full-course plan, not the previous solution). Baseline measured in the same
run: re-solving the whole REMAINING course with the full-course OCP from the rider's
state at a few points of the race (`ocp.solve_plan` with `start=`, warm from the plan, as
the engine's `course_replan` does when the rider leaves the plan): too slow to do at
every replan, which is the point. Every plan and
horizon is solved for `simulate.planning_conditions` (the lateral grip the virtual rider
uses), so the race's planner believes the truth.

Run: `.venv/bin/python bench/bench_closed_loop.py [--quick]` (--quick: 1 km horizon only,
a quarter of the race). The race itself is one run per horizon: its ~1000 replans are the
sample whose median / p95 / max are printed; the cold and baseline figures are medians
over their sample points.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import time
from pathlib import Path

import numpy as np

from itt_planner.course.loader import load_course
from itt_planner.live.course_replan import start_from
from itt_planner.live.engine import EngineSettings
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import PRESETS
from itt_planner.ocp.cache import load_or_solve
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.course_settings import OcpSettings
from itt_planner.ocp.horizon import HorizonPlanner
from itt_planner.ocp.horizon_settings import HorizonSettings
from itt_planner.sim import planning_conditions, simulate_ride

RIDER = PRESETS["paper"]


def _stats(x: list[float]) -> dict[str, float]:
    a = np.asarray(x)
    return {"n": len(a), "median": float(np.median(a)), "p95": float(np.percentile(a, 95)),
            "max": float(a.max())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json", type=Path, help="also write the figures here (after each stage)")
    args = ap.parse_args()
    logging.disable(logging.WARNING)
    course = load_course("verona-like")
    # Plans for the lateral grip the virtual rider uses (belief = truth in nominal).
    belief = planning_conditions(Conditions())
    plan = load_or_solve(course, RIDER, belief, OcpSettings(), "3d")
    print(f"verona-like {course.length_m / 1000:.2f} km, plan {plan.finish_time_s:.1f} s "
          f"({plan.solver_status}); load average {os.getloadavg()[0]:.1f}", flush=True)
    results: dict[str, object] = {"plan_finish_time_s": plan.finish_time_s}
    horizons = (1000.0,) if args.quick else (1000.0, 500.0)
    max_time = plan.finish_time_s / 4 if args.quick else None
    for horizon in horizons:
        planner = HorizonPlanner(course, RIDER, plan, conditions=belief,
                                 settings=HorizonSettings(horizon_m=horizon))
        t0 = time.perf_counter()
        # Every advice a horizon solve (no advising the plan itself while the rider is on
        # it): this measures the replan latency, and a nominal race stays on the plan.
        res = simulate_ride(course, RIDER, plan, planner=planner, seed=0,
                            engine_settings=EngineSettings(on_plan_band_j=0.0),
                            max_time_s=max_time)
        wall = time.perf_counter() - t0
        warm = _stats(res.solve_times_s)
        cold_times = []
        for advice in res.advice[::10]:
            planner.reset()
            t1 = time.perf_counter()
            planner.solve(advice.state)
            cold_times.append(time.perf_counter() - t1)
        cold = _stats(cold_times)
        over_1s = sum(t > 1.0 for t in res.solve_times_s)
        results[f"horizon_{horizon:.0f}m"] = {
            "warm": warm, "cold": cold, "replans_over_1s": over_1s,
            "fallbacks": res.fallbacks, "finish_time_s": res.finish_time_s,
            "race_wall_s": wall,
        }
        print(f"H={horizon:.0f} m: race {wall:.0f} s wall, finish {res.finish_time_s:.1f} s, "
              f"{warm['n']} replans, {res.fallbacks} fallbacks, {over_1s} over 1 s")
        print(f"  warm  median {warm['median'] * 1e3:6.0f} ms  p95 {warm['p95'] * 1e3:6.0f} ms  "
              f"max {warm['max'] * 1e3:6.0f} ms")
        print(f"  cold  median {cold['median'] * 1e3:6.0f} ms  p95 {cold['p95'] * 1e3:6.0f} ms  "
              f"max {cold['max'] * 1e3:6.0f} ms  ({cold['n']} states)", flush=True)
        _write(args.json, results)
    # Baseline: the whole remaining course, re-solved at a few points of the race.
    points = (0.5,) if args.quick else (0.25, 0.5, 0.75)
    full = []
    for frac in points:
        advice = res.advice[int(frac * len(res.advice))]
        s = advice.state.s_m
        start = start_from(planner, advice.state, s)
        t0 = time.perf_counter()
        sol = solve_plan(course, RIDER, belief, guess=plan, start=start)
        full.append(time.perf_counter() - t0)
        print(f"  remaining course from {s / 1000:.1f} km "
              f"({(course.length_m - s) / 1000:.1f} km): {full[-1]:.1f} s "
              f"({sol.solver_status}, {sol.iterations} iterations)", flush=True)
    base = float(np.median(full))
    results["remaining_course_resolve_s"] = {"points": list(points), "times_s": full,
                                             "median": base}
    for horizon in horizons:
        r = results[f"horizon_{horizon:.0f}m"]
        ratio = base / r["warm"]["median"]  # type: ignore[index]
        r["speedup_vs_remaining_course"] = ratio  # type: ignore[index]
        print(f"H={horizon:.0f} m: warm replan median is {ratio:.0f}x faster than re-solving "
              f"the remaining course (median {base:.1f} s)")
    results["load_average_end"] = os.getloadavg()
    _write(args.json, results)


def _write(path: Path | None, results: dict[str, object]) -> None:
    if path is not None:
        path.write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
