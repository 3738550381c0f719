"""Physics check: a model's forward run against the ride it replays.

Figures (distance-weighted over the ride's grid, so a stop does not count for its
minutes): finish-time error against the ride's moving time, speed MAE / RMSE / bias
(model minus ride) against the ride's 5 s smoothed speed, the share of distance within
+-2 km/h, the same per kilometre and per corner, and the noise floor: the MAE of the
raw GPS speed against that same smoothed speed (a model cannot be judged closer than
the ride's own sensors agree).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from itt_planner.calibration.forward import ForwardRun
from itt_planner.calibration.ride_on_course import RideOnCourse
from itt_planner.course.geometry import Course

#: Band of the "share within" figure (km/h).
BAND_KMH = 2.0


def _speed_figures(err_kmh: np.ndarray) -> dict[str, float]:
    return {"mae_kmh": round(float(np.mean(np.abs(err_kmh))), 3),
            "rmse_kmh": round(float(np.sqrt(np.mean(err_kmh ** 2))), 3),
            "bias_kmh": round(float(np.mean(err_kmh)), 3),
            "share_within_2kmh": round(float(np.mean(np.abs(err_kmh) <= BAND_KMH)), 4)}


def physics_check(run: ForwardRun, ride: RideOnCourse, course: Course) -> dict[str, Any]:
    """The figures of the module docstring for one model run."""
    err = 3.6 * (run.v_mps - ride.v_mps)
    real = ride.moving_time_s
    out: dict[str, Any] = {
        "model": run.model, "conditions": run.label,
        "finish_s": round(run.finish_time_s, 1),
        "ride_moving_s": round(real, 1),
        "finish_error_pct": round(100.0 * (run.finish_time_s / real - 1.0), 3),
        **_speed_figures(err),
        "noise_floor_kmh": round(ride.noise_floor_kmh(), 3),
    }
    if run.ride_inputs is not None:
        out["ride_inputs"] = run.ride_inputs
    km = np.floor((ride.s_m - ride.s_m[0]) / 1000.0).astype(int)
    out["per_km"] = [{"km": int(k), **_speed_figures(err[km == k]),
                      "time_error_s": round(float(_span_time(run.t_s, km == k)
                                                  - _span_time(ride.t_moving_s, km == k)), 2)}
                     for k in np.unique(km)]
    corners = []
    for c in course.corners:
        inside = (ride.s_m >= c.entry_s_m) & (ride.s_m <= c.exit_s_m)
        if inside.sum() < 2:
            continue
        corners.append({"apex_s_m": round(c.apex_s_m, 1), "radius_m": round(c.min_radius_m, 1),
                        "ride_min_kmh": round(3.6 * float(ride.v_mps[inside].min()), 1),
                        "model_min_kmh": round(3.6 * float(run.v_mps[inside].min()), 1),
                        **_speed_figures(err[inside])})
    out["per_corner"] = corners
    return out


def _span_time(t_s: np.ndarray, mask: np.ndarray) -> float:
    idx = np.flatnonzero(mask)
    return float(t_s[idx[-1]] - t_s[idx[0]]) if len(idx) > 1 else 0.0
