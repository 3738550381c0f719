"""Scenario sweeps on Ray: throughput against workers and a plain loop, overhead, memory.

In one run, on a 1.2 km built course (the tests' `short-1200m`):

1. throughput: the same 3D cases (2 riders x 3 winds x 2 directions x dry/wet = 24) by a
   plain loop of `solve_case` in a fresh process, and by `run_sweep` on a private local
   Ray instance with 1 and 2 workers; cases per minute at steady state (from the first
   finished case to the last, so each process's one-off NLP build is left out alike) and
   end to end (Ray's start and stop included); median of `--repeats` runs each;
2. Ray's overhead per case: a 1-worker sweep's steady wall time per case minus the mean
   time the worker spent in `solve_case` for the same cases (what Ray and the driver add
   between cases), and the round trip of a no-op actor call;
3. memory per worker over a 200-case sweep of 1D cases (2 riders x 10 winds x 5
   directions x dry/wet) on 2 workers: each worker's peak RSS after its 10th, 50th and
   last case, and the slope of a straight line through its second half (kB per case);
4. what a 32-core cluster would give: cases/min = 32 x 60 / (the measured per-case cost
   on one worker), for 3D cases of this course and scaled to a full course.

Run: .venv/bin/python bench/bench_sweep.py [--repeats 3] [--memory-cases 200]
The machine is shared: the load average is printed with each figure.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from support.courses import SHORT

from itt_planner.sweep import load_spec, run_sweep, solve_case
from itt_planner.sweep.cases import expand, load_inputs
from itt_planner.sweep.cluster import ray_session
from itt_planner.sweep.solve import CaseSolver
from itt_planner.sweep.store import ResultStore


def load() -> str:
    return "/".join(f"{x:.1f}" for x in os.getloadavg())


def write_spec(folder: Path, name: str, axes: dict[str, Any]) -> Path:
    (folder / "short.yaml").write_text(yaml.safe_dump(SHORT))
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump({"name": name, "courses": ["short.yaml"],
                                    "riders": ["typical", "climber"], "axes": axes}))
    return path


def _loop(spec_path: Path) -> dict[str, Any]:
    spec = load_spec(spec_path)
    courses, riders = load_inputs(spec)
    cases = expand(spec, courses, riders)
    stamps, walls = [], []
    t0 = time.perf_counter()
    for c in cases:
        walls.append(solve_case(courses[c.course], c)["case_wall_s"])
        stamps.append(time.perf_counter())
    return {"cases": len(cases),
            "cases_per_min_end_to_end": 60 * len(cases) / (stamps[-1] - t0),
            "cases_per_min_steady": 60 * (len(cases) - 1) / (stamps[-1] - stamps[0]),
            "mean_case_s": statistics.mean(walls[1:])}


def plain_loop(spec_path: Path) -> dict[str, Any]:
    """`_loop` in a fresh process (its NLP cache cold, like a new Ray worker's), with one
    OpenMP thread as Ray gives a 1-CPU worker (it sets OMP_NUM_THREADS=1), so that both
    run the same code the same way (without it, one run of the loop was 25 % slower than
    one Ray worker on the loaded 2-core machine)."""
    os.environ["OMP_NUM_THREADS"] = "1"  # read by the spawned child at its start
    try:
        with multiprocessing.get_context("spawn").Pool(1) as pool:
            return pool.apply(_loop, (spec_path,))
    finally:
        del os.environ["OMP_NUM_THREADS"]


def ray_sweep(spec_path: Path, workers: int, folder: Path) -> dict[str, Any]:
    spec = load_spec(spec_path)
    out = Path(tempfile.mkdtemp(dir=folder)) / "r.parquet"
    stamps: list[float] = []
    t0 = time.perf_counter()
    summary = run_sweep(spec, out, workers=workers,
                        on_row=lambda _: stamps.append(time.perf_counter()))
    end_to_end = time.perf_counter() - t0
    rows = ResultStore(out).read().to_pylist()
    steady = stamps[-1] - stamps[0]
    first = min(r["finished_unix_s"] for r in rows)
    return {"cases": summary.solved, "workers": summary.workers,
            "first_case_s": stamps[0] - t0, "end_to_end_s": end_to_end,
            "cases_per_min_end_to_end": 60 * summary.solved / end_to_end,
            "cases_per_min_steady": 60 * (len(stamps) - 1) / steady,
            # The cases after the first finished one: those the steady rate counts.
            "mean_case_s": statistics.mean(r["case_wall_s"] for r in rows
                                           if r["finished_unix_s"] > first),
            "rows": rows}


def noop_round_trip(n: int = 200) -> float:
    """Median seconds of one call to an actor method that does nothing (whoami)."""
    import ray  # noqa: PLC0415

    with ray_session(workers=1):
        actor: Any = ray.remote(num_cpus=1)(CaseSolver).remote()
        ray.get(actor.whoami.remote())
        times = []
        for _ in range(n):
            t = time.perf_counter()
            ray.get(actor.whoami.remote())
            times.append(time.perf_counter() - t)
    return statistics.median(times)


def memory(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    out = []
    for pid in sorted({r["pid"] for r in rows}):
        mine = sorted((r["worker_cases"], r["worker_peak_rss_mb"]) for r in rows if r["pid"] == pid)
        n, rss = np.array(mine).T
        late = n >= n.max() / 2
        slope_kb = float(np.polyfit(n[late], rss[late], 1)[0] * 1024)
        at = {int(k): float(v) for k, v in mine}
        out.append({"pid": pid, "cases": len(mine), "rss_mb_at_10": at.get(10),
                    "rss_mb_at_50": at.get(50), "rss_mb_last": float(rss[-1]),
                    "slope_kb_per_case": round(slope_kb, 2)})
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--memory-cases", type=int, default=200)
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="bench_sweep"))
    spec3d = write_spec(folder, "tput3d", {"model": ["3d"], "wind_kmh": [0, 20, 40],
                                           "wind_from_deg": [90, 270], "mu": [1.0, 0.6]})
    print(f"load {load()}: warm-up (compiles the kernels once per machine)", flush=True)
    spec = load_spec(spec3d)
    courses, riders = load_inputs(spec)
    solve_case(courses[spec.courses[0]], expand(spec, courses, riders)[0])
    runs: dict[str, list[dict[str, Any]]] = {"loop": [], "ray1": [], "ray2": []}
    for i in range(args.repeats):
        runs["loop"].append(plain_loop(spec3d))
        runs["ray1"].append(ray_sweep(spec3d, 1, folder))
        runs["ray2"].append(ray_sweep(spec3d, 2, folder))
        print(f"repeat {i + 1}: load {load()}: "
              f"loop {runs['loop'][-1]['cases_per_min_steady']:.1f}, "
              f"ray1 {runs['ray1'][-1]['cases_per_min_steady']:.1f}, "
              f"ray2 {runs['ray2'][-1]['cases_per_min_steady']:.1f} cases/min (steady)", flush=True)

    def med(kind: str, key: str) -> float:
        return float(statistics.median(r[key] for r in runs[kind]))

    loop_cpm = med("loop", "cases_per_min_steady")
    result: dict[str, Any] = {"load_avg_end": load(), "cases_3d": runs["loop"][0]["cases"]}
    for kind in ("loop", "ray1", "ray2"):
        result[f"{kind}_cases_per_min_steady"] = round(med(kind, "cases_per_min_steady"), 1)
        result[f"{kind}_cases_per_min_end_to_end"] = round(
            med(kind, "cases_per_min_end_to_end"), 1)
        result[f"{kind}_mean_case_s"] = round(med(kind, "mean_case_s"), 3)
        result[f"{kind}_vs_loop"] = round(med(kind, "cases_per_min_steady") / loop_cpm, 3)
    for kind in ("ray1", "ray2"):
        result[f"{kind}_first_case_s"] = round(med(kind, "first_case_s"), 1)
    # Overhead per case: what a 1-worker sweep spends per case beyond solve_case itself.
    per_case_ray1 = 60.0 / med("ray1", "cases_per_min_steady")
    overheads = [60.0 / r["cases_per_min_steady"] - r["mean_case_s"] for r in runs["ray1"]]
    result["ray1_per_case_s"] = round(per_case_ray1, 3)
    result["ray_overhead_per_case_s"] = round(statistics.median(overheads), 4)
    result["noop_actor_round_trip_ms"] = round(1000 * noop_round_trip(), 3)
    # Memory over a long 1D sweep.
    winds = np.linspace(0, 45, 10).round(1).tolist()
    n_dirs = max(1, args.memory_cases // (2 * 10 * 2))
    directions = np.linspace(0, 360, n_dirs, endpoint=False).round(1).tolist()
    spec1d = write_spec(folder, "mem1d", {"model": ["1d"], "wind_kmh": winds,
                                          "wind_from_deg": directions,
                                          "mu": [1.0, 0.6]})
    mem_run = ray_sweep(spec1d, 2, folder)
    result["memory_cases"] = mem_run["cases"]
    result["memory_1d_cases_per_min_steady"] = round(mem_run["cases_per_min_steady"], 1)
    result["memory_per_worker"] = memory(mem_run["rows"])
    # A 32-core cluster: 32 workers each at the measured per-case cost (ideal scaling:
    # no shared state between cases, the driver's work per case is ~the no-op round trip).
    result["cluster_32_cases_per_min_short_3d"] = round(32 * 60.0 / per_case_ray1, 0)
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
