"""Plan check: the optimal plan for the calibrated rider against the ride it came from.

As the paper's Tables 1-2: predicted against real finish (the ride's moving time over
the same stretch of course), where the time was won or lost (per climb, descent, flat
and corner: plan time minus ride time on that stretch, negative where the plan is
faster), and the power MAE (plan against ride, both on the ride's grid, the ride's power
averaged over 30 s, as a rider reads a target).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from itt_planner.calibration.ride_on_course import RideOnCourse
from itt_planner.course.geometry import Course
from itt_planner.ocp.plan import Plan

#: Grade above which a stretch is a climb (below minus it, a descent), over 200 m.
SECTION_GRADE = 0.02
#: Stretches shorter than this join their neighbour.
MIN_SECTION_M = 300.0


def sections(course: Course, s0: float, s1: float) -> list[tuple[str, float, float]]:
    """Climbs, descents and flats between `s0` and `s1`: (kind, start, end)."""
    grid = np.arange(s0, s1, 10.0)
    if len(grid) < 2:
        return [("flat", s0, s1)]
    z = course.at("z_m", grid)
    win = 20  # 200 m
    kernel = np.ones(win) / win
    grade = np.gradient(np.convolve(np.pad(z, win // 2, mode="edge"), kernel, "same")
                        [win // 2: win // 2 + len(z)], grid)
    kind = np.where(grade > SECTION_GRADE, "climb",
                    np.where(grade < -SECTION_GRADE, "descent", "flat"))
    runs: list[list[Any]] = []
    for k, g in zip(grid, kind, strict=True):
        if runs and runs[-1][0] == g:
            runs[-1][2] = k
        else:
            runs.append([g, k, k])
    merged: list[list[Any]] = []
    for run in runs:
        if merged and (run[2] - run[1] < MIN_SECTION_M or merged[-1][0] == run[0]):
            merged[-1][2] = run[2]
        else:
            merged.append(run)
    merged[-1][2] = s1
    return [(str(k), float(a), float(b)) for k, a, b in merged]


def plan_check(plan: Plan, ride: RideOnCourse, course: Course) -> dict[str, Any]:
    """The figures of the module docstring for one plan."""
    s = ride.s_m
    t_plan = plan.at("t_s", s) - float(plan.at("t_s", s[0]))
    t_ride = ride.t_moving_s - ride.t_moving_s[0]
    p_ride = np.convolve(ride.power_w, np.ones(30) / 30, mode="same") if len(s) > 30 else \
        ride.power_w
    # Plan power is at the contact point and negative when braking: the rider's is >= 0.
    p_plan = np.clip(plan.at("power_w", s), 0.0, None)

    def won(a: float, b: float) -> float:
        return float((np.interp(b, s, t_plan) - np.interp(a, s, t_plan))
                     - (np.interp(b, s, t_ride) - np.interp(a, s, t_ride)))

    rows: list[dict[str, Any]] = [{"kind": k, "start_m": round(a, 0), "end_m": round(b, 0),
             "plan_minus_ride_s": round(won(a, b), 1)} for k, a, b in sections(course, s[0], s[-1])]
    rows += [{"kind": "corner", "start_m": round(c.entry_s_m, 0), "end_m": round(c.exit_s_m, 0),
              "radius_m": round(c.min_radius_m, 1),
              "plan_minus_ride_s": round(won(c.entry_s_m, c.exit_s_m), 2)}
             for c in course.corners if s[0] <= c.entry_s_m and c.exit_s_m <= s[-1]]
    by_kind = {k: round(sum(r["plan_minus_ride_s"] for r in rows if r["kind"] == k), 1)
               for k in ("climb", "descent", "flat", "corner")}
    return {
        "model": plan.model, "solver_status": plan.solver_status,
        "converged": bool(plan.meta.get("success", False)),
        "plan_finish_s": round(float(t_plan[-1]), 1), "ride_moving_s": round(float(t_ride[-1]), 1),
        "plan_minus_ride_pct": round(100.0 * (float(t_plan[-1]) / float(t_ride[-1]) - 1.0), 2),
        "power_mae_w": round(float(np.mean(np.abs(p_plan - p_ride))), 1),
        "plan_mean_power_w": round(float(np.mean(p_plan)), 1),
        "ride_mean_power_w": round(float(np.mean(ride.power_w)), 1),
        "time_by_kind_s": by_kind, "sections": rows,
    }
