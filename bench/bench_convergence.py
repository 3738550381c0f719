"""Convergence study of the full-course OCP (issue 18 item 4): models x courses x meshes.

For each course and model (1D, 3D) the plan is solved on the default non-uniform mesh and
on meshes of half and double its spacing (`h_min_m`, `h_max_m`, `h_max_1d_m` scaled by
0.5 and 2), each from the cold default guess (with the restart strategies of `ocp`), and
the row says: status (`solver.PlanStatus`), IPOPT's status, iterations, the strategies
used, nodes, wall time, CPU time (the solve's `cpu_s`; `child_cpu_s` the whole child
process with imports and verification), finish time, whether the plan passed its
verification (and its worst mismatch). Then per course: the finish-time differences
between the meshes, and each 1D against the 3D on the same mesh (the 1D finish should be within
0.3 % of the 3D finish on courses without tight corners; the course's smallest corner
radius is printed beside it).

Models: `1d` (model.md section 6, on the centre line), `1d-line` (the same 1D on the
shortest line within the road less the edge margin, `ocp.line_plan`: the 1D's own
time-optimal path, as the 3D plan takes its own line on the road's width; the row's
`line_ratio` is the line's length over the centre line's), `3d`.

Courses: the demo courses, the real tracks (`../shared/data`, skipped when absent), and
course-builder courses with a climb, a technical descent, a hilly route with a -6.9 %
descent and the 2-lap 4 km loop of issue 18. Rider: the issue's (86 kg, CdA 0.273 m^2,
CP 290 W, otherwise the paper calibration).

Each case runs in a fresh child process (one case's memory or a crash cannot colour the
next); rows are printed as they come and, with `--jsonl FILE`, appended to FILE.

Run: .venv/bin/python -m bench.bench_convergence [--models 1d,1d-line,3d] [--meshes 1,0.5,2]
     [--courses NAME,...] [--jsonl FILE]
Wall times on a shared, loaded machine: the load average is printed with every row.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import resource
import time
from pathlib import Path
from queue import Empty
from typing import Any

from support.courses import loop_4k_lap

from itt_planner.course.builder import build_course
from itt_planner.course.geometry import Course
from itt_planner.course.loader import load_course
from itt_planner.model.rider import Rider
from itt_planner.units import MPS_TO_KMH

RIDER = Rider(name="issue18", mass_kg=86.0, drag_area_m2=0.273, critical_power_w=290.0)
DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
REAL = {"tokyo2020": DATA / "courses" / "tokyo2020_olympic_itt_lap.csv",
        "bologna": DATA / "rides" / "zwift_bologna_tt_virtual.tcx",
        "stjohns": DATA / "rides" / "edge810_vector_stjohns_2013.fit"}


BUILT: dict[str, dict[str, Any]] = {
    "loop-4k-2laps": {"segments": loop_4k_lap() + loop_4k_lap()},
    "climb-3.9k": {"segments": [
        {"type": "straight", "length_m": 300, "grade_pct": 2},
        {"type": "straight", "length_m": 1200, "grade_pct": 6},
        {"type": "arc", "angle_deg": 60, "radius_m": 40, "direction": "right", "grade_pct": 7},
        {"type": "straight", "length_m": 1200, "grade_pct": 8},
        {"type": "arc", "angle_deg": 60, "radius_m": 40, "direction": "left", "grade_pct": 7},
        {"type": "straight", "length_m": 1054, "grade_pct": 5}]},
    "descent-hairpins": {"segments": [
        {"type": "straight", "length_m": 600, "grade_pct": -7},
        {"type": "clothoid", "length_m": 15, "radius_m": 12, "direction": "left",
         "grade_pct": -7},
        {"type": "arc", "angle_deg": 150, "radius_m": 12, "direction": "left", "grade_pct": -7},
        {"type": "clothoid", "length_m": 15, "grade_pct": -7},
        {"type": "straight", "length_m": 500, "grade_pct": -9},
        {"type": "clothoid", "length_m": 15, "radius_m": 9, "direction": "right",
         "grade_pct": -9},
        {"type": "arc", "angle_deg": 160, "radius_m": 9, "direction": "right", "grade_pct": -9},
        {"type": "clothoid", "length_m": 15, "grade_pct": -9},
        {"type": "straight", "length_m": 800, "grade_pct": -12}]},
    "hilly-9k": {"segments": [
        {"type": "straight", "length_m": 2000, "grade_pct": 1},
        {"type": "straight", "length_m": 1500, "grade_pct": 5.5},
        {"type": "arc", "angle_deg": 45, "radius_m": 60, "direction": "left", "grade_pct": 4},
        {"type": "straight", "length_m": 1800, "grade_pct": -6.9},
        {"type": "arc", "angle_deg": 60, "radius_m": 50, "direction": "right",
         "grade_pct": -3},
        {"type": "straight", "length_m": 3100, "grade_pct": 0.5}]},
}
DEFAULT_COURSES = ("verona-like", "rovereto-like", *REAL, *BUILT)
MODELS = ("1d", "1d-line", "3d")


def course_by_name(name: str) -> Course:
    if name in BUILT:
        return build_course({"name": name, **BUILT[name]})
    if name in REAL:
        if not REAL[name].exists():
            raise FileNotFoundError(f"{REAL[name]} (../shared/data absent)")
        return load_course(REAL[name])
    return load_course(name)


def _case(name: str, model: str, scale: float, queue: mp.Queue[dict[str, Any]]) -> None:
    import numpy as np  # noqa: PLC0415

    from itt_planner.ocp.course_problem import solve_plan  # noqa: PLC0415
    from itt_planner.ocp.course_settings import OcpSettings  # noqa: PLC0415
    from itt_planner.ocp.line_plan import solve_plan_on_line  # noqa: PLC0415

    row: dict[str, Any] = {"course": name, "model": model, "mesh": scale}
    try:
        course = course_by_name(name)
        base = OcpSettings()
        settings = OcpSettings(h_min_m=base.h_min_m * scale, h_max_m=base.h_max_m * scale,
                               h_max_1d_m=base.h_max_1d_m * scale)
        t0, c0 = time.perf_counter(), time.process_time()
        if model == "1d-line":
            plan = solve_plan_on_line(course, RIDER, settings=settings)
        else:
            plan = solve_plan(course, RIDER, settings=settings, model=model)
        cpu_s = time.process_time() - c0
        ver = plan.meta.get("verification") or {}
        row |= {"length_km": round(course.length_m / 1000, 2),
                "min_radius_m": round(min((c.min_radius_m for c in course.corners),
                                          default=float("inf")), 1),
                "status": plan.status, "ipopt": plan.meta.get("ipopt_status"),
                "iterations": plan.iterations, "nodes": plan.n_nodes,
                "strategies": "+".join(a["strategy"] for a in plan.meta.get("attempts", [])),
                "wall_s": round(time.perf_counter() - t0, 1), "cpu_s": round(cpu_s, 1),
                "finish_s": round(plan.finish_time_s, 2),
                "verified": ver.get("verified"), "worst": ver.get("worst"),
                "worst_ratio": ver.get("worst_ratio"),
                "max_speed_error_mps": ver.get("max_speed_error_mps"),
                "v_max_kmh": round(MPS_TO_KMH * float(np.max(plan.v_mps)), 1),
                "line_ratio": plan.meta.get("line", {}).get("length_ratio")}
    except Exception as err:  # noqa: BLE001 - a bench row records any failure
        row |= {"status": "error", "error": f"{type(err).__name__}: {err}"[:200]}
    row["load"] = "/".join(f"{x:.1f}" for x in os.getloadavg())
    queue.put(row)


def run_case(name: str, model: str, scale: float) -> dict[str, Any]:
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=_case, args=(name, model, scale, queue))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc.start()
    row: dict[str, Any] = {}
    # Take the row while the child lives (it may block on the queue's pipe until read).
    while not row and (proc.is_alive() or not queue.empty()):
        try:
            row = queue.get(timeout=1.0)
        except Empty:
            continue
    proc.join()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if not row:
        row = {"course": name, "model": model, "mesh": scale, "status": "error",
               "error": f"child exited with {proc.exitcode}"}
    # The whole child (imports, course, solve, verification): user + system CPU seconds.
    row["child_cpu_s"] = round(after.ru_utime + after.ru_stime
                               - before.ru_utime - before.ru_stime, 1)
    return row


def summary(rows: list[dict[str, Any]]) -> str:
    """Markdown: the rows, then mesh and model differences per course."""
    cols = ("course", "model", "mesh", "status", "ipopt", "iterations", "strategies", "nodes",
            "wall_s", "cpu_s", "finish_s", "verified", "worst_ratio", "load")
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(str(r.get(c, r.get("error", "")) if c != "ipopt" else
                                    r.get("ipopt", r.get("error", ""))) for c in cols) + " |"
              for r in rows]
    lines.append("")
    by = {(r["course"], r["model"], r["mesh"]): r for r in rows if "finish_s" in r}
    for course in dict.fromkeys(r["course"] for r in rows):
        parts = []
        for model in MODELS:
            ref = by.get((course, model, 1.0))
            if ref is None:
                continue
            for scale in (0.5, 2.0):
                other = by.get((course, model, scale))
                if other is not None:
                    diff = 100 * (other["finish_s"] - ref["finish_s"]) / ref["finish_s"]
                    parts.append(f"{model} mesh x{scale:g} {diff:+.3f} %")
        for scale in (1.0, 0.5, 2.0):  # each 1D against the 3D on the same mesh
            three = by.get((course, "3d", scale))
            for model in MODELS[:2]:
                one = by.get((course, model, scale))
                if one and three:
                    diff = 100 * (one["finish_s"] - three["finish_s"]) / three["finish_s"]
                    parts.append(f"{model} vs 3d x{scale:g} {diff:+.3f} %")
        if parts:
            radius = next(r["min_radius_m"] for r in rows
                          if r["course"] == course and "min_radius_m" in r)
            parts.append(f"smallest corner radius {radius} m")
        if parts:
            lines.append(f"- {course}: " + "; ".join(parts))
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default=",".join(MODELS))
    ap.add_argument("--meshes", default="1,0.5,2")
    ap.add_argument("--courses", default=",".join(DEFAULT_COURSES))
    ap.add_argument("--jsonl", type=Path, default=None)
    args = ap.parse_args()
    rows = []
    # Model and mesh outermost: the cheap 1D rows first, then 3D on the default mesh.
    for model in args.models.split(","):
        for scale in (float(x) for x in args.meshes.split(",")):
            for name in [c for c in args.courses.split(",") if c]:
                row = run_case(name, model, scale)
                rows.append(row)
                print(json.dumps(row), flush=True)
                if args.jsonl is not None:
                    with args.jsonl.open("a") as fh:
                        fh.write(json.dumps(row) + "\n")
    print(summary(rows))


if __name__ == "__main__":
    main()
