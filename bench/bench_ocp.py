"""Full-course OCP benchmark: 3D and 1D solves vs a naive Opti baseline.

Prints, per case, the median wall time of >= 3 runs, iterations, nodes, finish time and
the process's peak RSS; and the ratio against the naive baseline (uniform 2 m mesh,
casadi.Opti on MX, IPOPT defaults) measured here on the first `BASELINE_M` metres of
the same course (the whole course takes minutes that way), scaled per node.
Run: .venv/bin/python bench/bench_ocp.py [--runs 3] [--courses verona-like,rovereto-like]
"""

from __future__ import annotations

import argparse
import resource
import statistics
import time

import casadi as ca
import numpy as np

from itt_planner.course_loader import load_course
from itt_planner.mesh import build_mesh, road_data
from itt_planner.model import ModelParams, build_3d
from itt_planner.ocp import OcpSettings, bounds, initial_guess, solve_plan, start_speed
from itt_planner.conditions import Conditions
from itt_planner.rider import PRESETS

BASELINE_M = 1000.0


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def naive_baseline(course, rider, length_m: float) -> tuple[float, int, int]:
    """Opti + MX, uniform 2 m mesh, one RK4 step per interval, IPOPT defaults."""
    model = build_3d()
    nodes = build_mesh(course, uniform_m=2.0, end_m=length_m)
    n = len(nodes) - 1
    road = road_data(course, nodes)
    par = ModelParams(rider, Conditions()).vector()
    opti = ca.Opti()
    x = opti.variable(model.nx, n + 1)
    u = opti.variable(model.nu, n)
    cost = 0
    for k in range(n):
        h = road[3, k]
        rk = [road[:, k]]
        k1, t1, j1 = model.ode(x[:, k], u[:, k], rk[0], par)
        k2, t2, j2 = model.ode(x[:, k] + h / 2 * k1, u[:, k], rk[0], par)
        k3, t3, j3 = model.ode(x[:, k] + h / 2 * k2, u[:, k], rk[0], par)
        k4, t4, j4 = model.ode(x[:, k] + h * k3, u[:, k], rk[0], par)
        opti.subject_to(x[:, k + 1] == x[:, k] + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4))
        cost += h / 6 * (j1 + 2 * j2 + 2 * j3 + j4)
        opti.subject_to(model.path(x[:, k + 1], par) <= 0)
    xg, ug = initial_guess(model, course, nodes, rider, Conditions(),
                           start_speed(rider, Conditions(), OcpSettings()))
    (lbx, ubx), _ = bounds(model, course, nodes, rider, OcpSettings(), xg[:, 0])
    opti.subject_to(opti.bounded(lbx, x, ubx))
    opti.set_initial(x, np.clip(xg, lbx, ubx))
    opti.minimize(cost)
    opti.solver("ipopt", {"print_time": False}, {"print_level": 0, "sb": "yes", "max_iter": 1000})
    t0 = time.perf_counter()
    try:
        opti.solve()
        it = opti.stats()["iter_count"]
    except RuntimeError:
        it = opti.debug.stats()["iter_count"]
    return time.perf_counter() - t0, it, n + 1


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--courses", default="verona-like,rovereto-like")
    args = ap.parse_args()
    rider = PRESETS["typical"]
    for name in args.courses.split(","):
        course = load_course(name)
        t_base, it_base, n_base = naive_baseline(course, rider, BASELINE_M)
        print(f"{name}: naive baseline (Opti/MX, uniform 2 m, IPOPT defaults) on the first "
              f"{BASELINE_M:.0f} m: {t_base:.1f} s, {it_base} it, {n_base} nodes "
              f"({1000 * t_base / n_base:.2f} ms/node)", flush=True)
        for model in ("1d", "3d"):
            times, plan = [], None
            for _ in range(args.runs):
                t0 = time.perf_counter()
                plan = solve_plan(course, rider, model=model)
                times.append(time.perf_counter() - t0)
            med = statistics.median(times)
            per_node = med / plan.n_nodes
            print(f"  {model}: median {med:.2f} s of {args.runs} (runs {', '.join(f'{t:.2f}' for t in times)}), "
                  f"{plan.iterations} it, {plan.n_nodes} nodes, status {plan.solver_status}, "
                  f"finish {plan.finish_time_s:.1f} s, peak RSS {peak_mb():.0f} MB, "
                  f"per-node ratio vs naive x{(t_base / n_base) / per_node:.1f}", flush=True)


if __name__ == "__main__":
    main()
