"""Where the same-ride replay's speed error comes from (issue 15, "speed MAE within 1 km/h
of the raw-speed noise floor"): each hypothesis measured on the real rides.

Per ride (tests/data/ or ../shared/data/): the rider calibrated on the same ride
(`calibrate`, the Zwift ride with `allow_virtual`), then the 1D replay of `validate_ride`
(day wind, the ride's braking and stops: `physics[-1]`) with one input changed at a time:

1. time lags between the signals: the lags of altitude and power behind speed that best
   close the power balance (a 2-parameter grid on 9 s means of the climb rate the power
   explains minus the altimeter's), then the replay with the course's altitude shifted
   along the road by `v * lag` and the power shifted in time, over a sweep of lags;
2. the elevation source (`calibration.ride_elevation`): the ride's own altitude per 1 m
   of course (matched as the replay matches power and speed), Gaussian-smoothed over L
   (sigma L/2), and the same with its short-scale part (< 1 km) averaged over every pass
   of each place; the course's own profile is the baseline (`elevation="course"`), and
   `validate`'s default (`"auto"`: the ride's, passes averaged, 60 m) a row;
3. rotating mass: E3's kinetic term with the wheels' inertia (`m + I/r^2`, 1.6 kg: two
   700c wheels of 0.09 kg m^2 at r = 0.335 m), through a wrapped 1D ODE (model/ unchanged);
4. noise floors: the floor `validate` reports (raw GPS speed vs the 5 s device speed),
   the device's own raw-vs-5 s spread, GPS vs device both 5 s smoothed, and, where the
   ride passes its places twice, the elevation floor: the MAE between two replays on the
   profile of one pass and of the other (two equally valid readings of the same road);
5. one wind per 10 min (`fit_day_wind` per window) instead of one per ride (a replay loop
   with per-interval parameters, otherwise `forward_1d`'s);
6. where places are passed twice, how much of the error is the place's (what a better
   profile, a fixed wind or a corner could explain: it repeats at every pass) and how
   much changes between passes (gusts, position, drafting): validate's default replay's
   error in `REPEAT_BIN_M` means, against the other pass's at the same place.

With `--3d` the 3D replay too: on the course's profile, validate's default (the ride's
altitude, `ride_elevation`) and, where places are passed twice, the passes averaged at 100 m.
Not timings: fits and replays, one run. Run:
`.venv/bin/python -m bench.bench_replay_error [--3d] [NAME...]`.
"""

from __future__ import annotations

import dataclasses
import sys
from typing import Any
from unittest import mock

import casadi as ca
import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial import cKDTree
from support.real_data import RIDES, locate

from itt_planner.calibration import CalibrationError, CalibrationOptions, calibrate
from itt_planner.calibration.aero import fit_day_wind
from itt_planner.calibration.calibrate import load_rides
from itt_planner.calibration.forward import ForwardRun, _brake_to
from itt_planner.calibration.matching import course_progress
from itt_planner.calibration.physics_check import physics_check
from itt_planner.calibration.ride_data import RideSeries, smooth
from itt_planner.calibration.ride_elevation import (
    PASS_APART_M,
    PASS_RADIUS_M,
    SMOOTHING_M,
    altitude_on_course,
    pass_readings,
    with_profile,
)
from itt_planner.calibration.ride_inputs import ride_inputs
from itt_planner.calibration.ride_on_course import RideOnCourse, ride_on_course
from itt_planner.calibration.validate import ride_conditions, validate_ride
from itt_planner.course.geometry import Course
from itt_planner.course.loader import load_course
from itt_planner.model import dynamics
from itt_planner.model.conditions import GRAVITY_MPS2
from itt_planner.model.params import PARAMS, ROAD, ModelParams
from itt_planner.model.rider import Rider
from itt_planner.units import MPS_TO_KMH

#: Rotating mass of two 700c wheels, I/r^2 (kg).
WHEELS_KG = 2 * 0.09 / 0.335 ** 2
#: Wind windows of hypothesis 5 (s).
WIND_WINDOW_S = 600.0
#: Bins of hypothesis 6 (m): longer than the replay's memory of an error (drag's time
#: constant m / (rho CdA v) ~ 20 s, ~200 m), so a bin's mean is its own.
REPEAT_BIN_M = 250.0


def figures(series: RideSeries, course: Course, rider: Rider, model: str = "1d",
            elevation: str = "course") -> dict[str, Any]:
    """The replay with the ride's inputs in the day's wind (the figures the target is on),
    on `course`'s own profile unless `elevation` says otherwise."""
    out: dict[str, Any] = validate_ride(series, course, rider, models=(model,),
                                        elevation=elevation).figures
    if "physics_3d" in out:
        return {"mae_kmh": float("nan"), "finish_error_pct": float("nan"), "rmse_kmh": float("nan")}
    phys: dict[str, Any] = out["physics"][-1]
    return phys


def show(tag: str, p: dict[str, Any]) -> dict[str, float]:
    row = {k: p[k] for k in ("finish_error_pct", "mae_kmh", "rmse_kmh")}
    print(f"  {tag:46s} finish {row['finish_error_pct']:+6.2f} %  MAE {row['mae_kmh']:.2f}  "
          f"RMSE {row['rmse_kmh']:.2f} km/h", flush=True)
    return row


def time_shift(series: RideSeries, x: np.ndarray, lag_s: float) -> np.ndarray:
    """x(t + lag) within each block: a signal recorded `lag_s` late, put back in time."""
    out = x.astype(float).copy()
    for b in np.unique(series.block):
        i = np.flatnonzero(series.block == b)
        out[i] = np.interp(series.t_s[i] + lag_s, series.t_s[i], x[i])
    return out


def balance_lags(series: RideSeries, rider: Rider) -> tuple[float, float, float, float]:
    """Lags (s) of altitude and power behind speed that close the power balance best:
    the climb rate the power explains, `(P - m v a - crr m g v - rho CdA v^3/2)/(m g)`,
    against the altimeter's, both as 9 s means over pedalled samples (> 40 W, > 3 m/s).
    Returns (altitude lag, power lag, RMS at the best, RMS at no lag) (m/s)."""
    m, g = rider.mass_kg, GRAVITY_MPS2
    ok = smooth(((series.v_mps > 3.0) & (series.power_w > 40.0)).astype(float), series.block,
                9) > 0.999
    taus = np.arange(-5.0, 8.01, 0.5)

    def rms(tv: float, th: float) -> float:
        v = time_shift(series, series.v_mps, tv)
        rate = (series.power_w - m * v * np.gradient(v) - rider.crr * m * g * v
                - 0.5 * series.rho_kgpm3 * rider.drag_area_m2 * v ** 3) / (m * g)
        err = smooth(rate - np.gradient(time_shift(series, series.ele_m, th)), series.block, 9)
        return float(np.std(err[ok]))

    tab = np.array([[rms(tv, th) for th in taus] for tv in taus])
    i, j = np.unravel_index(np.argmin(tab), tab.shape)
    zero = int(np.argmin(np.abs(taus)))
    # v(t + tv) and h(t + th) match P(t): behind speed, altitude lags th - tv, power -tv.
    return float(taus[j] - taus[i]), float(-taus[i]), float(tab[i, j]), float(tab[zero, zero])


def rotating_mass_1d(extra_kg: float) -> Any:
    """`build_1d` whose dv/ds has the wheels' inertia in the kinetic term only:
    `(m + m_rot) dv/dt = F` (gravity, rolling and drag on m as before)."""
    def build() -> dynamics.SpatialModel:
        base = dynamics.build_1d()
        x, u = ca.SX.sym("x", base.nx), ca.SX.sym("u", base.nu)
        road, p = ca.SX.sym("road", len(ROAD)), ca.SX.sym("p", len(PARAMS))
        dx, dt, dj = base.ode(x, u, road, p)
        m = p[PARAMS.index("mass")]
        ode = ca.Function("ode1d_rot", [x, u, road, p],
                          [ca.vertcat(dx[0] * m / (m + extra_kg), dx[1:]), dt, dj],
                          ["x", "u", "road", "p"], ["dxds", "dtds", "dJds"])
        return dataclasses.replace(base, ode=ode)
    return build


def windowed_wind_replay(course: Course, rider: Rider, series: RideSeries,
                         ride: RideOnCourse) -> ForwardRun:
    """`forward_1d` with the ride's inputs, but one wind per `WIND_WINDOW_S` of the ride's
    clock (`fit_day_wind` on that window; the day's where it cannot be fitted)."""
    day_wind = fit_day_wind(series, rider.mass_kg, rider.crr, rider.drag_area_m2,
                            rider.drivetrain_efficiency)
    day = ride_conditions(series, day_wind)
    base = ModelParams(rider, day).vector()
    names = ("t_s", "v_mps", "power_w", "ele_m", "dist_m", "rho_kgpm3", "block", "lat_deg",
             "lon_deg", "gps_speed_mps")
    winds = []
    for a in np.arange(0.0, series.t_s[-1], WIND_WINDOW_S):
        lo, hi = np.searchsorted(series.t_s, [a, a + WIND_WINDOW_S])
        part = dataclasses.replace(series, **{k: getattr(series, k)[lo:hi] for k in names})
        try:
            winds.append(fit_day_wind(part, rider.mass_kg, rider.crr, rider.drag_area_m2,
                                      rider.drivetrain_efficiency))
        except CalibrationError:
            winds.append(day_wind)
    s = ride.s_m
    mid = 0.5 * (s[1:] + s[:-1])
    clock = np.interp(mid, s, ride.t_moving_s + ride.t_stopped_s)
    par = np.repeat(base[None, :], len(mid), 0)
    which = np.minimum((clock // WIND_WINDOW_S).astype(int), len(winds) - 1)
    par[:, PARAMS.index("wind_e")] = [winds[w][0] for w in which]
    par[:, PARAMS.index("wind_n")] = [winds[w][1] for w in which]
    model = dynamics.build_1d()
    step = dynamics.rk4_step(model, 2)
    kappa, beta, theta = (course.at(k, mid) for k in ("kappa_per_m", "beta_rad", "theta_rad"))
    w_n = np.clip(ride.power_w, 0.0, None) / rider.max_power_w
    inputs = ride_inputs(model, course, rider, ride, day)
    w_cell = np.where(inputs.brake_w_n < 0, inputs.brake_w_n, 0.5 * (w_n[1:] + w_n[:-1]))
    v, t = np.empty(len(s)), np.zeros(len(s))
    v[0] = max(float(ride.v_mps[0]), 1.0)
    x = np.array([v[0], w_n[0], 1.0])
    for k in range(len(mid)):
        if inputs.unseen[k] or inputs.launch[k]:
            x[0] = v[k + 1] = max(float(ride.v_mps[k + 1]), 0.5)
            t[k + 1] = t[k] + float(ride.moving_dt_s()[k])
            continue
        road = [float(kappa[k]), float(beta[k]), float(theta[k]), float(s[k + 1] - s[k])]
        if inputs.brake_w_n[k] < 0:
            x, dt, _ = _brake_to(step, x, road, par[k], float(inputs.brake_w_n[k]),
                                 float(ride.v_mps[k + 1]))
        else:
            x[1] = w_cell[k]
            xf, dt, _ = step(x, 0.0, road, par[k])
            x = np.asarray(xf).ravel()
        x[0], x[2] = max(x[0], 0.5), 1.0
        if inputs.stop[k]:
            x[0] = max(float(ride.v_mps[k + 1]), 1.0)
        v[k + 1], t[k + 1] = x[0], t[k] + float(dt)
    return ForwardRun("1d", "wind per window", s, v, t)


def floors(series: RideSeries, course: Course, ride: RideOnCourse) -> dict[str, float]:
    """Speed-measurement floors on the replay's grid (km/h)."""
    s = course_progress(course, series.lat_deg, series.lon_deg, series.t_s)
    idx = np.flatnonzero(np.isfinite(s) & (series.v_mps > 1.0))
    at = idx[np.concatenate([[True], np.diff(s[idx]) > 0])]
    gps = np.where(np.isfinite(series.gps_speed_mps), series.gps_speed_mps, series.v_mps)
    gps5 = np.interp(ride.s_m, s[at], smooth(gps, series.block, 5)[at])
    raw = np.interp(ride.s_m, s[at], series.v_mps[at])
    k = MPS_TO_KMH
    return {"as_defined": ride.noise_floor_kmh(),
            "device_raw_vs_5s": k * float(np.mean(np.abs(raw - ride.v_mps))),
            "gps_5s_vs_device_5s": k * float(np.mean(np.abs(gps5 - ride.v_mps)))}


def lag_rows(series: RideSeries, course: Course, rider: Rider, ride: RideOnCourse
             ) -> dict[str, Any]:
    """Hypothesis 1: the lags the balance finds, and replays over a sweep of lags."""
    lag_h, lag_p, best, zero = balance_lags(series, rider)
    print(f"  lags behind speed from the power balance: altitude {lag_h:+.1f} s, power "
          f"{lag_p:+.1f} s (9 s climb-rate misfit {best:.4f} vs {zero:.4f} m/s at none)")
    out: dict[str, Any] = {"lags": {"altitude_s": lag_h, "power_s": lag_p}}
    v_on_course = np.interp(course.s_m, ride.s_m, ride.v_mps)
    for lag in (-3.0, -1.5, 1.5, 3.0):
        z = np.interp(course.s_m + v_on_course * lag, course.s_m, course.z_m)
        out[f"alt_lag_{lag}"] = show(f"altitude lag {lag:+.1f} s",
                                     figures(series, with_profile(course, z), rider))
    for lag in (-3.0, -1.5, 1.5, 3.0):
        shifted = dataclasses.replace(series, power_w=time_shift(series, series.power_w, lag))
        out[f"power_lag_{lag}"] = show(f"power lag {lag:+.1f} s", figures(shifted, course, rider))
    return out


def elevation_rows(series: RideSeries, course: Course, rider: Rider
                   ) -> tuple[dict[str, Any], Course]:
    """Hypothesis 2 (and the elevation floor of 4): the ride's own altitude, smoothed, and
    averaged over the passes of each place. Returns the rows and the passes-averaged
    course at 100 m (the course itself without places passed twice)."""
    out: dict[str, Any] = {}
    raw, _ = altitude_on_course(series, course)
    for scale in (20.0, 60.0, 100.0):
        z = gaussian_filter1d(raw, scale / 2.0 / course.ds_m, mode="nearest")
        out[f"ride_alt_{scale:.0f}"] = show(f"ride altitude, smoothed {scale:.0f} m",
                                            figures(series, with_profile(course, z), rider))
    readings = pass_readings(course, raw)
    print(f"  {100 * readings.passed_share:.0f} % of the course passed twice or more")
    out["validate_auto"] = show(f"validate's default (auto: ride, {SMOOTHING_M:.0f} m)",
                                figures(series, course, rider, elevation="auto"))
    if readings.passed_share < 0.5:
        return out, course
    avg = readings.averaged()
    for scale in (60.0, 100.0):
        z = gaussian_filter1d(avg, scale / 2.0 / course.ds_m, mode="nearest")
        out[f"multipass_{scale:.0f}"] = show(f"passes averaged, smoothed {scale:.0f} m",
                                             figures(series, with_profile(course, z), rider))
    # Elevation floor: every place at one pass's reading, against the other pass's.
    first = course.s_m < 0.5 * course.length_m
    theirs = np.where(readings.other_passes > 0, readings.other_short, readings.short)
    runs = []
    for a, b in ((readings.short, theirs), (theirs, readings.short)):
        z = gaussian_filter1d(readings.low + np.where(first, a, b), 50.0 / course.ds_m,
                              mode="nearest")
        runs.append(validate_ride(series, with_profile(course, z), rider, models=("1d",),
                                  elevation="course").runs[-1])
    out["elevation_floor_kmh"] = MPS_TO_KMH * float(np.mean(np.abs(runs[0].v_mps
                                                                     - runs[1].v_mps)))
    print(f"  replays on one pass's profile vs the other's (100 m) differ by MAE "
          f"{out['elevation_floor_kmh']:.2f} km/h", flush=True)
    return out, with_profile(course, gaussian_filter1d(avg, 50.0 / course.ds_m, mode="nearest"))


def repeat_split(course: Course, ride: RideOnCourse, run: ForwardRun) -> dict[str, float]:
    """Hypothesis 6: the replay's speed error in `REPEAT_BIN_M` means, each bin against
    the mean of the other pass at the same place (course points within `PASS_RADIUS_M`,
    `PASS_APART_M` apart along it). With `a`, `b` the two passes' bin errors: the
    correlation of a and b, the MAE of (a + b) / 2 (the place's part, plus half of what
    changes) and of (a - b) / 2 (what changes between passes, halved). km/h."""
    err = np.interp(ride.s_m, run.s_m, run.v_mps) - ride.v_mps
    edges = np.arange(0.0, ride.s_m[-1] + REPEAT_BIN_M, REPEAT_BIN_M)
    which = np.digitize(ride.s_m, edges) - 1
    mean = np.bincount(which, err, len(edges)) / np.maximum(np.bincount(which, None,
                                                                        len(edges)), 1)
    xy = np.c_[course.x_m, course.y_m]
    on_grid = np.searchsorted(course.s_m, ride.s_m).clip(0, len(course.s_m) - 1)
    dist, idx = cKDTree(xy).query(xy[on_grid], k=32, distance_upper_bound=PASS_RADIUS_M)
    idx = np.where(np.isfinite(dist), idx, 0)
    other_s = np.where(np.isfinite(dist) & (np.abs(course.s_m[idx] - ride.s_m[:, None])
                                           >= PASS_APART_M), course.s_m[idx], np.nan)
    pairs = []  # (this bin, the other pass's bin at the same place), each pair once
    for k in range(len(edges) - 1):
        mine = which == k
        there = other_s[mine][np.isfinite(other_s[mine])]
        if mine.sum() and there.size > 0.5 * mine.sum():
            j = int(np.median(np.digitize(there, edges) - 1))
            if j > k:
                pairs.append((k, j))
    if len(pairs) < 4:
        return {}
    a, b = mean[[k for k, _ in pairs]], mean[[j for _, j in pairs]]
    out = {"bins": float(len(pairs)), "corr": float(np.corrcoef(a, b)[0, 1]),
           "place_mae_kmh": MPS_TO_KMH * float(np.mean(np.abs(a + b))) / 2,
           "between_passes_mae_kmh": MPS_TO_KMH * float(np.mean(np.abs(a - b))) / 2}
    print(f"  error at a place, pass against pass ({len(pairs)} bins of "
          f"{REPEAT_BIN_M:.0f} m): correlation {out['corr']:.2f}, MAE of the place's part "
          f"{out['place_mae_kmh']:.2f}, of the part that changes (halved) "
          f"{out['between_passes_mae_kmh']:.2f} km/h", flush=True)
    return out


def one_ride(relpath: str, with_3d: bool) -> dict[str, Any]:
    path = locate(relpath)
    assert path is not None
    course = load_course(path)
    options = CalibrationOptions(allow_virtual="zwift" in relpath)
    rider = calibrate([path], options, courses=[course]).rider
    series = load_rides([path], None)[0]
    ride = ride_on_course(series, course)
    print(f"{path.name}: CdA {rider.drag_area_m2:.3f}, mass {rider.mass_kg:.1f} kg", flush=True)
    out: dict[str, Any] = {"baseline": show("baseline (course profile)",
                                            figures(series, course, rider))}
    out["floors"] = floors(series, course, ride)
    print("  floors km/h: " + ", ".join(f"{k} {v:.2f}" for k, v in out["floors"].items()))
    out.update(lag_rows(series, course, rider, ride))
    rows, best_course = elevation_rows(series, course, rider)
    out.update(rows)
    with mock.patch("itt_planner.calibration.forward.build_1d", rotating_mass_1d(WHEELS_KG)):
        out["rotating_mass"] = show(f"wheels' inertia (+{WHEELS_KG:.1f} kg kinetic)",
                                    figures(series, course, rider))
    run = windowed_wind_replay(course, rider, series, ride)
    out["wind_per_10min"] = show("one wind per 10 min", physics_check(run, ride, course))
    default = validate_ride(series, course, rider, models=("1d",))
    out["repeat_split"] = repeat_split(course, default.on_course, default.runs[-1])
    if with_3d:
        out["3d_baseline"] = show("3D, course profile", figures(series, course, rider, "3d"))
        out["3d_auto"] = show("3D, validate's default (auto)",
                              figures(series, course, rider, "3d", "auto"))
        if best_course is not course:
            out["3d_multipass_100"] = show("3D, passes averaged, 100 m",
                                           figures(series, best_course, rider, "3d"))
    return out


def main(args: list[str]) -> int:
    with_3d = "--3d" in args
    names = [a for a in args if not a.startswith("--")]
    rides = [r for r in RIDES if "shanghai" not in r and (not names or any(n in r for n in names))]
    for relpath in rides:
        if locate(relpath) is None:
            print(f"{relpath}: not found, skipped")
            continue
        one_ride(relpath, with_3d)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
