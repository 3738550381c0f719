"""Receding-horizon replan latency along a course (from the full-course plan's states).

Replans every `--step` metres (about one replan period at race speed) with a warm
start, then the same states cold (warm start reset each time); prints median / p95 /
max latency, iterations and success counts, and the ratio against re-solving the
whole remaining course (measured on a few states).
Run: .venv/bin/python bench/bench_horizon.py [--course verona-like] [--horizon 1000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from itt_planner.course_loader import load_course
from itt_planner.horizon import HorizonPlanner, HorizonSettings
from itt_planner.ocp import solve_plan
from itt_planner.rider import PRESETS
from itt_planner.state import RiderState


def state_at(course, plan, s: float) -> RiderState:
    return RiderState(stamp_s=0.0, s_m=s, n_m=float(plan.at("n_m", s)),
                      speed_mps=float(plan.at("v_mps", s)),
                      heading_rad=float(course.at("theta_rad", s) + plan.at("alpha_rad", s)),
                      power_w=float(plan.at("power_w", s)),
                      w_prime_j=float(plan.at("w_prime_j", s)), elapsed_s=float(plan.at("t_s", s)))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--course", default="verona-like")
    ap.add_argument("--horizon", type=float, nargs="+", default=[1000.0, 500.0])
    ap.add_argument("--step", type=float, default=15.0)
    ap.add_argument("--until", type=float, default=None, help="stop at this s (m)")
    args = ap.parse_args()
    course = load_course(args.course)
    rider = PRESETS["typical"]
    plan = solve_plan(course, rider, model="3d")
    print(f"plan: {plan.solver_status}, {plan.finish_time_s:.1f} s, {plan.solve_time_s:.1f} s solve")
    end = min(args.until or course.length_m, course.length_m - 20)
    states = [state_at(course, plan, s) for s in np.arange(0.0, end, args.step)]
    for horizon in args.horizon:
        planner = HorizonPlanner(course, rider, plan, settings=HorizonSettings(horizon_m=horizon))
        for mode in ("warm", "cold"):
            lat, its, ok = [], [], 0
            for st in states:
                if mode == "cold":
                    planner.reset()
                sol = planner.solve(st)
                lat.append(sol.solve_time_s)
                its.append(sol.iterations)
                ok += sol.success
            lat_a = np.array(lat)
            print(f"H={horizon:.0f} m {mode}: {len(states)} replans, median {1000 * np.median(lat_a):.0f} ms, "
                  f"p95 {1000 * np.percentile(lat_a, 95):.0f} ms, max {1000 * lat_a.max():.0f} ms, "
                  f"over 1 s: {(lat_a > 1).sum()}, median it {np.median(its):.0f}, "
                  f"success {ok}/{len(states)}", flush=True)
    # Baseline: re-solve the whole remaining course from a few states.
    base = []
    for s in (course.length_m * 0.25, course.length_m * 0.5):
        from itt_planner.course import Course  # noqa: PLC0415

        i = int(s / course.ds_m)
        rest = Course.from_centerline(course.name + "-rest", course.x_m[i:], course.y_m[i:],
                                      course.z_m[i:], origin=course.origin)
        t0 = time.perf_counter()
        solve_plan(rest, rider, model="3d")
        base.append(time.perf_counter() - t0)
    print(f"re-solving the remaining course (from 25 % and 50 %): {', '.join(f'{b:.1f}' for b in base)} s"
          f" -> ratio vs median warm replan x{np.median(base) / np.median(lat_a):.0f} (last horizon)")


if __name__ == "__main__":
    main()
