"""The advice's horizon: a solution (or the full-course plan) cut at the rider's position.

`Solution` is what the engine keeps of its last good horizon solve (a fallback shifts it
forward); `from_plan` makes one of the full-course plan (the advice while the rider
keeps to it, and the fallback before any good solve); `advice_fields` cuts one at the
rider's `s` into the `Advice` arrays (the line in ENU and WGS84) and projections.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.model.state import RiderState
from itt_planner.ocp.plan import Plan


@dataclass(frozen=True)
class Solution:
    """A horizon solution from `state`: arrays over `s_m`, and its projections."""

    state: RiderState
    s_m: np.ndarray
    t_s: np.ndarray
    power_w: np.ndarray
    v_mps: np.ndarray
    n_m: np.ndarray
    w_prime_j: np.ndarray
    predicted_finish_s: float
    w_prime_finish_j: float


def from_plan(plan: Plan, course: Course, state: RiderState, horizon_m: float,
              w_prime_max_j: float) -> Solution:
    """The full-course plan over `horizon_m` from the rider, with the rider's W'."""
    p = plan
    end = min(state.s_m + horizon_m, course.length_m)
    inside = (p.s_m > state.s_m) & (p.s_m < end)
    s = np.concatenate([[state.s_m], p.s_m[inside], [end]])
    t_plan = p.at("t_s", s)
    w_plan = p.at("w_prime_j", s)
    w_end = state.w_prime_j + float(p.w_prime_j[-1] - w_plan[0])
    return Solution(
        state=state, s_m=s, t_s=t_plan - t_plan[0], power_w=p.at("power_w", s),
        v_mps=p.at("v_mps", s), n_m=p.at("n_m", s),
        w_prime_j=state.w_prime_j + (w_plan - w_plan[0]),
        predicted_finish_s=state.elapsed_s + p.finish_time_s - float(t_plan[0]),
        w_prime_finish_j=min(w_end, w_prime_max_j),
    )


def advice_fields(course: Course, state: RiderState, sol: Solution) -> dict[str, Any]:
    """The `Advice` keyword arguments of `sol` cut to start at the rider's `s`: horizon
    arrays, the line, the finish projections (a solution made earlier - a fallback -
    keeps the time the rider lost or gained against it since)."""
    keep = sol.s_m > state.s_m
    s = np.concatenate([[state.s_m], sol.s_m[keep]])

    def cut(a: np.ndarray) -> np.ndarray:
        return np.concatenate([[np.interp(state.s_m, sol.s_m, a)], a[keep]])

    t_then = float(np.interp(state.s_m, sol.s_m, sol.t_s))
    late = (state.elapsed_s - sol.state.elapsed_s) - t_then
    n = cut(sol.n_m)
    return {"horizon_s_m": s, "horizon_power_w": cut(sol.power_w),
            "horizon_speed_mps": cut(sol.v_mps), "horizon_n_m": n,
            **line_fields(course, s, n),
            "predicted_finish_s": sol.predicted_finish_s + late,
            "w_prime_now_j": state.w_prime_j,
            "w_prime_finish_j": sol.w_prime_finish_j + (state.w_prime_j - float(
                np.interp(state.s_m, sol.s_m, sol.w_prime_j)))}


def finished_fields(course: Course, state: RiderState) -> dict[str, Any]:
    """The `Advice` keyword arguments past the finish line: a one-node horizon here."""
    s = np.array([state.s_m])
    n = np.array([state.n_m])
    return {"horizon_s_m": s, "horizon_power_w": np.zeros(1),
            "horizon_speed_mps": np.array([state.speed_mps]), "horizon_n_m": n,
            **line_fields(course, s, n), "predicted_finish_s": state.elapsed_s,
            "w_prime_now_j": state.w_prime_j, "w_prime_finish_j": state.w_prime_j}


def line_fields(course: Course, s_m: np.ndarray, n_m: np.ndarray) -> dict[str, np.ndarray]:
    """The line through `(s, n)` in the ENU map frame and in WGS84."""
    x, y, z = course.enu_at(s_m, n_m)
    lat, lon, _ = course.to_geodetic(x, y, z)
    return {"line_x_m": np.asarray(x), "line_y_m": np.asarray(y), "line_z_m": np.asarray(z),
            "line_lat_deg": np.asarray(lat), "line_lon_deg": np.asarray(lon)}
