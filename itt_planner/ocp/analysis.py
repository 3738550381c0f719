"""Analysis of plans on one course: its longest climb and descent, and the three virtual
riders (model.md section 7) compared with both models (`compare_riders`, the CLI's
`compare-riders`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import PRESETS
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.course_settings import OcpSettings


def longest_stretch(course: Course, climbing: bool, grade_min: float = 0.01
                    ) -> tuple[float, float]:
    """(start, end) in m of the longest stretch steeper than `grade_min` up (`climbing`)
    or down; (0, 0) if there is none."""
    grade = np.tan(course.beta_rad)
    steep = grade > grade_min if climbing else grade < -grade_min
    best, start = (0.0, 0.0), None
    for i, d in enumerate(np.append(steep, False)):
        if d and start is None:
            start = i
        elif not d and start is not None:
            if course.s_m[i - 1] - course.s_m[start] > best[1] - best[0]:
                best = (float(course.s_m[start]), float(course.s_m[i - 1]))
            start = None
    return best


def longest_descent(course: Course) -> tuple[float, float]:
    """(start, end) in m of the longest stretch that loses height (grade < -1 %)."""
    return longest_stretch(course, climbing=False)


def compare_riders(course: Course, conditions: Conditions = Conditions(),
                   settings: OcpSettings = OcpSettings()) -> list[dict[str, Any]]:
    """The three virtual riders (model.md section 7) x both models on one course.

    Per row: finish time, time on the longest descent and on the longest climb, time
    through the sharpest corner.
    """
    d0, d1 = longest_descent(course)
    c0, c1 = longest_stretch(course, climbing=True)
    sharpest = min(course.corners, key=lambda c: c.min_radius_m, default=None)
    rows: list[dict[str, Any]] = []
    for name in ("typical", "specialist", "climber"):
        for kind in ("3d", "1d"):
            plan = solve_plan(course, PRESETS[name], conditions, settings, model=kind)
            corner_t = (float(plan.at("t_s", sharpest.exit_s_m)
                              - plan.at("t_s", sharpest.entry_s_m)) if sharpest else 0.0)
            rows.append({
                "rider": name, "model": kind, "finish_time_s": round(plan.finish_time_s, 2),
                "descent_time_s": round(float(plan.at("t_s", d1) - plan.at("t_s", d0)), 2),
                "climb_time_s": round(float(plan.at("t_s", c1) - plan.at("t_s", c0)), 2),
                "corner_time_s": round(corner_t, 2), "status": plan.status,
                "solver_status": plan.solver_status, "solve_time_s": round(plan.solve_time_s, 2)})
    return rows
