"""Physics check: a model's forward run against the ride it replays.

Figures (distance-weighted over the ride's grid, so a stop does not count for its
minutes): finish-time error against the ride's moving time, speed MAE / RMSE / bias
(model minus ride) against the ride's 5 s smoothed speed, the share of distance within
+-2 km/h, the same per kilometre and per corner, and the noise floor: the MAE of the
raw GPS speed against that same smoothed speed (a model cannot be judged closer than
the ride's own sensors agree).

What the replay cannot model is reported where it is, with the time the model lost
there and the figures outside it, beside the whole ride's (never instead): sheltered
stretches (`shelter`: drafting, a local tail wind) and corners the ride rounds beyond
the road's grip (a virtual ride's game has no cornering physics: the 3D virtual rider
brakes there, the game's rider did not).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from itt_planner.calibration.forward import ForwardRun
from itt_planner.calibration.ride_on_course import RideOnCourse
from itt_planner.course.geometry import Course
from itt_planner.model.conditions import GRAVITY_MPS2
from itt_planner.units import MPS_TO_KMH

#: Band of the "share within" figure (km/h).
BAND_KMH = 2.0
#: A corner taken beyond grip costs a grip-limited model its braking before and its
#: speeding up after: the zone its time is counted over (m before entry, after exit).
BEYOND_GRIP_BEFORE_M = 100.0
BEYOND_GRIP_AFTER_M = 500.0


def _speed_figures(err_kmh: np.ndarray) -> dict[str, float]:
    return {"mae_kmh": round(float(np.mean(np.abs(err_kmh))), 3),
            "rmse_kmh": round(float(np.sqrt(np.mean(err_kmh ** 2))), 3),
            "bias_kmh": round(float(np.mean(err_kmh)), 3),
            "share_within_2kmh": round(float(np.mean(np.abs(err_kmh) <= BAND_KMH)), 4)}


def physics_check(run: ForwardRun, ride: RideOnCourse, course: Course,
                  grip_mps2: float = GRAVITY_MPS2) -> dict[str, Any]:
    """The figures of the module docstring for one model run (`grip_mps2`: the road's
    lateral grip, `mu_y g` of the conditions)."""
    err = MPS_TO_KMH * (run.v_mps - ride.v_mps)
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
    if run.sheltered is not None and run.sheltered.any():
        out.update(_shelter_figures(run, ride, err))
    out.update(_beyond_grip_figures(run, ride, course, err, grip_mps2))
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
                        "ride_min_kmh": round(MPS_TO_KMH * float(ride.v_mps[inside].min()), 1),
                        "model_min_kmh": round(MPS_TO_KMH * float(run.v_mps[inside].min()), 1),
                        **_speed_figures(err[inside])})
    out["per_corner"] = corners
    return out


def _shelter_figures(run: ForwardRun, ride: RideOnCourse, err_kmh: np.ndarray
                     ) -> dict[str, Any]:
    """The time the model lost in each sheltered stretch (`shelter`: it rides them solo)
    and the figures outside them."""
    assert run.sheltered is not None
    lost = np.diff(run.t_s) - ride.moving_dt_s()
    stretches = run.ride_inputs["sheltered"] if run.ride_inputs else []
    per = []
    for st in stretches:
        span = ((ride.s_m[:-1] >= st["from_m"] - 1e-6)
                & (ride.s_m[:-1] < st["from_m"] + st["length_m"] - 1e-6))
        per.append({"from_km": round(st["from_m"] / 1000.0, 2), "length_m": st["length_m"],
                    "model_minus_ride_s": round(float(lost[span].sum()), 1)})
    return {"sheltered_time_lost": per,
            "outside_sheltered": _outside(run, ride, err_kmh, run.sheltered)}


def _beyond_grip_figures(run: ForwardRun, ride: RideOnCourse, course: Course,
                         err_kmh: np.ndarray, grip_mps2: float) -> dict[str, Any]:
    """Corners the ride rounds with more lateral acceleration (`v^2 kappa` at the ride's
    speed) than `grip_mps2` gives: a game without cornering physics (a virtual ride), or
    a course curvature the road does not have. A model that corners by grip (3D) must
    lose time there; the time it lost from `BEYOND_GRIP_BEFORE_M` before each to
    `BEYOND_GRIP_AFTER_M` after (braking, and speeding up again) and the figures outside
    these zones. Empty without such corners."""
    zone = np.zeros(len(ride.s_m) - 1, bool)
    corners = []
    for c in course.corners:
        inside = (ride.s_m >= c.entry_s_m) & (ride.s_m <= c.exit_s_m)
        if inside.sum() < 2:
            continue
        a_y = ride.v_mps[inside] ** 2 * np.abs(course.at("kappa_per_m", ride.s_m[inside]))
        if a_y.max() <= grip_mps2:
            continue
        here = ((ride.s_m[:-1] >= c.entry_s_m - BEYOND_GRIP_BEFORE_M)
                & (ride.s_m[:-1] <= c.exit_s_m + BEYOND_GRIP_AFTER_M))
        zone |= here
        corners.append({"apex_km": round(c.apex_s_m / 1000.0, 3),
                        "radius_m": round(c.min_radius_m, 1),
                        "ride_lateral_accel_mps2": round(float(a_y.max()), 1),
                        "ride_min_kmh": round(MPS_TO_KMH * float(ride.v_mps[inside].min()), 1),
                        "model_min_kmh": round(MPS_TO_KMH * float(run.v_mps[inside].min()), 1)})
    if not corners:
        return {}
    lost = np.diff(run.t_s) - ride.moving_dt_s()
    return {"corners_beyond_grip": corners,
            "beyond_grip": {"grip_mps2": round(grip_mps2, 2),
                            "model_minus_ride_s": round(float(lost[zone].sum()), 1),
                            "zone_m": round(float(np.diff(ride.s_m)[zone].sum()), 1)},
            "outside_beyond_grip": _outside(run, ride, err_kmh, zone)}


def _outside(run: ForwardRun, ride: RideOnCourse, err_kmh: np.ndarray, inside: np.ndarray
             ) -> dict[str, Any]:
    """Finish error over the ride's moving time outside the intervals `inside`, and the
    speed errors on the grid points outside them."""
    lost = np.diff(run.t_s) - ride.moving_dt_s()
    rest = float(ride.moving_dt_s()[~inside].sum())
    point_in = np.concatenate([inside, [False]]) | np.concatenate([[False], inside])
    return {"finish_error_pct": round(100.0 * float(lost[~inside].sum()) / rest, 3),
            "ride_moving_s": round(rest, 1), **_speed_figures(err_kmh[~point_in])}


def _span_time(t_s: np.ndarray, mask: np.ndarray) -> float:
    idx = np.flatnonzero(mask)
    return float(t_s[idx[-1]] - t_s[idx[0]]) if len(idx) > 1 else 0.0


def unmodelled_lines(p: dict[str, Any]) -> list[str]:
    """What a physics check's run could not model, a phrase each (`validate` and the
    report print them): sheltered stretches and corners beyond grip, with the time the
    model lost there and the figures outside them."""
    lines = []
    if "outside_sheltered" in p:
        per = p["sheltered_time_lost"]
        lost = sum(st["model_minus_ride_s"] for st in per)
        places = ", ".join(f"km {st['from_km']:.1f} ({st['length_m'] / 1000:.1f} km, "
                           f"{st['model_minus_ride_s']:+.0f} s)" for st in per)
        lines.append(f"sheltered (drafting or a local tail wind: the ride paid >= 30 % less "
                     f"air drag than the rider alone): {len(per)} stretches, "
                     f"{p['ride_inputs']['sheltered_m'] / 1000:.1f} km, the model {lost:+.0f} s "
                     f"there ({places}); outside them: " + _short(p["outside_sheltered"]))
    if "beyond_grip" in p:
        corners = p["corners_beyond_grip"]
        worst = max(c["ride_lateral_accel_mps2"] for c in corners)
        lines.append(f"{len(corners)} corners ridden beyond the road's grip (lateral "
                     f"acceleration up to {worst} m/s^2 > {p['beyond_grip']['grip_mps2']}: a "
                     "game without cornering physics, or a curvature the road does not have): "
                     f"the model {p['beyond_grip']['model_minus_ride_s']:+.0f} s there; "
                     "outside them: " + _short(p["outside_beyond_grip"]))
    return lines


def _short(o: dict[str, Any]) -> str:
    return f"finish {o['finish_error_pct']:+.2f} %, speed MAE {o['mae_kmh']} km/h"
