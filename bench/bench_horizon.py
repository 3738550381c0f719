"""Receding-horizon replan latency over a whole course (states from the plan, perturbed).

Replans every `--step` metres of course (about 3-7 replan periods at race speed) from
the full-course plan's state there, perturbed (speed x N(1, 3 %), line +- N(0, 0.3 m),
W' - U(0, 1500 J); seeded), first with the warm start (previous solution shifted), then
the same states cold (warm start reset each time). Prints median / p95 / max latency,
iterations and usable replans (success within the engine's 1 s overrun limit; budget-
capped "Suboptimal_Feasible" iterates counted separately) per horizon, and the ratio
against re-solving the whole remaining course with `ocp.solve_plan` (two states only).
Run: .venv/bin/python bench/bench_horizon.py [--course verona-like] [--horizon 1000 500]
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import time

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.course.loader import load_course
from itt_planner.live.engine import EngineSettings
from itt_planner.model.rider import PRESETS
from itt_planner.model.state import RiderState
from itt_planner.ocp.cache import load_or_solve
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.horizon import HorizonPlanner
from itt_planner.ocp.horizon_settings import HorizonSettings
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import PlanStatus


def state_at(course: Course, plan: Plan, s: float) -> RiderState:
    return RiderState(stamp_s=0.0, s_m=s, n_m=float(plan.at("n_m", s)),
                      speed_mps=float(plan.at("v_mps", s)),
                      heading_rad=float(course.at("theta_rad", s) + plan.at("alpha_rad", s)),
                      power_w=float(plan.at("power_w", s)),
                      w_prime_j=float(plan.at("w_prime_j", s)), elapsed_s=float(plan.at("t_s", s)))


def perturbed(state: RiderState, rng: np.random.Generator) -> RiderState:
    return dataclasses.replace(
        state, speed_mps=state.speed_mps * (1 + 0.03 * rng.standard_normal()),
        n_m=state.n_m + 0.3 * rng.standard_normal(),
        w_prime_j=max(0.0, state.w_prime_j - rng.uniform(0.0, 1500.0)))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--course", default="verona-like")
    ap.add_argument("--horizon", type=float, nargs="+", default=[1000.0, 500.0])
    ap.add_argument("--step", type=float, default=50.0)
    ap.add_argument("--until", type=float, default=None, help="stop at this s (m)")
    ap.add_argument("--baseline", type=int, default=2, help="full re-solves (0: skip)")
    args = ap.parse_args()
    logging.disable(logging.WARNING)  # failed replans are counted below
    course = load_course(args.course)
    rider = PRESETS["typical"]
    plan = load_or_solve(course, rider)
    print(f"plan: {plan.solver_status}, {plan.finish_time_s:.1f} s")
    end = min(args.until or course.length_m, course.length_m - 20)
    rng = np.random.default_rng(0)
    states = [perturbed(state_at(course, plan, s), rng) for s in np.arange(0.0, end, args.step)]
    median_warm = {}
    for horizon in args.horizon:
        planner = HorizonPlanner(course, rider, plan, settings=HorizonSettings(horizon_m=horizon))
        for mode in ("warm", "cold"):
            lat, its, ok, wmin, subopt = [], [], 0, np.inf, 0
            for st in states:
                if mode == "cold":
                    planner.reset()
                sol = planner.solve(st)
                lat.append(sol.solve_time_s)
                its.append(sol.iterations)
                # What the engine can use: a success within its 1 s overrun limit.
                ok += sol.success and sol.solve_time_s <= EngineSettings().max_solve_time_s
                subopt += sol.success and sol.outcome is PlanStatus.CAPPED
                if sol.success:
                    wmin = min(wmin, float(sol.w_prime_j.min()))
            lat_a = np.array(lat)
            if mode == "warm":
                median_warm[horizon] = float(np.median(lat_a))
            print(f"H={horizon:.0f} m {mode}: {len(states)} replans, "
                  f"median {1000 * np.median(lat_a):.0f} ms, "
                  f"p95 {1000 * np.percentile(lat_a, 95):.0f} ms, max {1000 * lat_a.max():.0f} ms, "
                  f"over 1 s: {(lat_a > 1).sum()}, median it {np.median(its):.0f}, "
                  f"usable {ok}/{len(states)} ({100 * ok / len(states):.1f} %, "
                  f"{subopt} suboptimal), "
                  f"min W' {wmin:.1f} J", flush=True)
    base = []
    for frac in (0.25, 0.5)[: args.baseline]:
        i = int(course.length_m * frac / course.ds_m)
        rest = Course.from_centerline(course.name + "-rest", course.x_m[i:], course.y_m[i:],
                                      course.z_m[i:], origin=course.origin)
        t0 = time.perf_counter()
        solve_plan(rest, rider, model="3d")
        base.append(time.perf_counter() - t0)
    if base:
        starts = ", ".join(f"{f:.0%}" for f in (0.25, 0.5)[: len(base)])
        print(f"re-solving the remaining course (from {starts}): "
              f"{', '.join(f'{b:.1f}' for b in base)} s; ratio vs median warm replan: "
              + ", ".join(f"H={h:.0f} m x{np.median(base) / m:.0f}"
                          for h, m in median_warm.items()))


if __name__ == "__main__":
    main()
