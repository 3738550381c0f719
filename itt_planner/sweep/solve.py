"""Solving one sweep case into one result row, and the Ray actor that does it on a worker.

`solve_case` is plain Python (the direct loop and the tests call it too); it never
raises: a failure of any kind (invalid rider on this equipment, unusable input, a crash
inside the solver) becomes a row with status "failed" and the reason, and a solve that
stops without converging a row with status "not_converged" and its figures, so one case
never stops the sweep. `CaseSolver` is the worker: one per CPU, it holds the courses it
was sent (fetched from Ray's object store once) and lives as long as the sweep, so the
NLP `ocp.solve_plan` builds for a course and model (cached per process) is built once per
worker, not once per case.
"""

from __future__ import annotations

import logging
import os
import resource
import socket
import time
from typing import Any

from itt_planner.course.geometry import Course
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.plan import splits
from itt_planner.sweep.cases import Case
from itt_planner.view.report import average_power_w

log = logging.getLogger(__name__)

CONVERGED = "converged"
NOT_CONVERGED = "not_converged"
FAILED = "failed"
STATUSES = (CONVERGED, NOT_CONVERGED, FAILED)


def case_labels(case: Case) -> dict[str, Any]:
    """The input columns of a case's row (SI units)."""
    return {"key": case.key, "course": case.course, "rider": case.rider_label,
            "equipment": case.equipment.name, "model": case.model,
            "wprime_model": case.settings.wprime_model.value,
            "wind_speed_mps": case.conditions.wind_speed_mps,
            "wind_from_rad": case.conditions.wind_from_rad, "mu": case.conditions.mu_x}


def failed_row(case: Case, reason: str, solver_status: str = "") -> dict[str, Any]:
    """The row of a case that produced no plan."""
    return {**case_labels(case), "status": FAILED, "solver_status": solver_status,
            "reason": reason, "finished_unix_s": time.time()}


def solve_case(course: Course, case: Case) -> dict[str, Any]:
    """Solve one case on `course` and return its row (never raises; module docstring)."""
    t0 = time.perf_counter()
    try:
        rider = case.equipment.apply(case.rider)
        plan = solve_plan(course, rider, case.conditions, case.settings, model=case.model)
    except Exception as err:  # noqa: BLE001 - any failure is this case's result, not the sweep's
        status = getattr(err, "status", "")
        log.warning("sweep case %s (%s, %s, %s) failed: %s", case.key, case.course,
                    case.rider_label, case.model, err)
        return {**failed_row(case, f"{type(err).__name__}: {err}", status),
                "case_wall_s": time.perf_counter() - t0}
    converged = bool(plan.meta.get("success", False))
    marks = splits(plan, case.split_every_m)
    return {
        **case_labels(case),
        "status": CONVERGED if converged else NOT_CONVERGED,
        "solver_status": plan.solver_status,
        "reason": "" if converged else (f"solver stopped without converging: "
                                        f"{plan.solver_status} after {plan.iterations} iterations"),
        "course_length_m": float(course.length_m),
        "mass_kg": rider.mass_kg, "drag_area_m2": rider.drag_area_m2,
        "critical_power_w": rider.critical_power_w, "w_prime_j": rider.w_prime_j,
        "finish_time_s": plan.finish_time_s,
        "mean_power_w": average_power_w(plan),
        "w_prime_end_j": float(plan.w_prime_j[-1]),
        "w_prime_min_j": float(plan.w_prime_j.min()),
        "split_s_m": [m["s_m"] for m in marks],
        "split_elapsed_s": [m["elapsed_s"] for m in marks],
        "iterations": plan.iterations, "n_nodes": plan.n_nodes,
        "solve_time_s": plan.solve_time_s,
        "build_time_s": float(plan.meta.get("build_time_s", float("nan"))),
        "case_wall_s": time.perf_counter() - t0,
        "finished_unix_s": time.time(),
    }


def peak_rss_mb() -> float:
    """This process's peak resident memory (MB, Linux `ru_maxrss` in kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


class CaseSolver:
    """A sweep worker (wrapped as a Ray actor by the runner): solves cases, keeps courses."""

    def __init__(self) -> None:
        self._courses: dict[str, Course] = {}
        self._solved = 0

    def solve(self, case: Case, course_ref: list[Any]) -> dict[str, Any]:
        """Solve `case`. `course_ref` is `[ObjectRef]` (in a list so that Ray hands the
        reference over instead of the course: it is fetched only the first time)."""
        import ray  # noqa: PLC0415 - only workers need it

        course = self._courses.get(case.course_key)
        if course is None:
            course = self._courses[case.course_key] = ray.get(course_ref[0])
        row = solve_case(course, case)
        self._solved += 1
        return {**row, **self.whoami(), "worker_cases": self._solved,
                "worker_peak_rss_mb": peak_rss_mb()}

    @staticmethod
    def whoami() -> dict[str, Any]:
        """Where this worker runs: Ray node id, host name, process id."""
        import ray  # noqa: PLC0415

        return {"node_id": ray.get_runtime_context().get_node_id(),
                "hostname": socket.gethostname(), "pid": os.getpid()}
