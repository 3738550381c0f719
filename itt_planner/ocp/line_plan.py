"""The 1D plan on the shortest line within the road (`course.racing_line`).

The 1D model (model.md section 6) ignores the corners, so its time-optimal path is the
shortest one within the road less the C11 edge margin. `solve_plan_on_line` solves the 1D
OCP on the course along that line (`racing_line.line_course`: its length, the road's
altitude over it, its heading for the wind) and hands back the plan on the road's arc
length, like any plan of the course: `s_m` on the centre line, `n_m` and `alpha_rad` the
line's, `t_s` and every other array as solved. The plan's verification (in `solve_plan`)
replayed it on the line's course, where it was solved; `meta["line"]` says so, with the
line's length.

Why: on the centre line the 1D rode a longer course than the 3D plan, which takes its
own line on the road's width: St John's 1D 3746.18 s against 3D 3732.81 s (+0.36 %), with
the 3D line 0.38 % shorter, worth 13.8 s of the 13.4 s (bench/RESULTS.md, 2026-12-02).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.course.racing_line import RacingLine, line_course
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import Rider
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.course_settings import OcpSettings
from itt_planner.ocp.plan import Plan


def solve_plan_on_line(course: Course, rider: Rider, conditions: Conditions = Conditions(),
                       settings: OcpSettings = OcpSettings()) -> Plan:
    """The 1D plan of `course` on its shortest line (`settings.margin_m` from the edges),
    on the road's arc length (module doc). Statuses and errors as `solve_plan`."""
    line = line_course(course, settings.margin_m)
    return onto_road(solve_plan(line.course, rider, conditions, settings, model="1d"), line)


def onto_road(plan: Plan, line: RacingLine) -> Plan:
    """A plan solved on `line.course`, on the road's arc length, with the line's offset
    and heading (and without the primal-dual point of its NLP, which is the line's)."""
    s_road = line.road_s(plan.s_m)
    n = np.interp(s_road, line.road.s_m, line.n_m)
    alpha = np.interp(s_road, line.road.s_m, line.alpha_rad)
    meta = {**plan.meta, "line": {"kind": "shortest", "course": line.course.name,
                                  "length_m": line.course.length_m,
                                  "length_ratio": line.length_ratio}}
    # The NLP point is that of the line's course: no re-solve of the road starts from it.
    return dataclasses.replace(plan, s_m=s_road, n_m=n, alpha_rad=alpha, meta=meta,
                               point_w=None, point_lam_x=None, point_lam_g=None)
