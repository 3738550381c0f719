"""Validate a rider and the planner against a real ride, and out of sample (hold-out).

`validate_ride` lays the ride on its course, replays its power through the model
(`forward`, physics check; on the ride's own altitude when the course is the ride's,
`ride_elevation`) and, on request, compares the optimal plan for the rider with it
(`plan_check`). The air density is the ride's (altitude and temperature).
`holdout` calibrates on all rides but one and validates on that one, for each ride.
"""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path
from typing import Any

import numpy as np

from itt_planner.calibration.aero import fit_day_wind, wind_meteo
from itt_planner.calibration.calibrate import CalibrationOptions, calibrate, load_rides
from itt_planner.calibration.elevation_check import check_course_elevation
from itt_planner.calibration.forward import ForwardRun, forward_1d, forward_3d
from itt_planner.calibration.physics_check import physics_check
from itt_planner.calibration.plan_check import plan_check
from itt_planner.calibration.ride_data import CalibrationError, RideSeries
from itt_planner.calibration.ride_elevation import is_ride_course, ride_elevation
from itt_planner.calibration.ride_on_course import RideOnCourse, ride_on_course
from itt_planner.course.geometry import Course
from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.rider import Rider

log = logging.getLogger(__name__)


@dataclasses.dataclass(eq=False)
class Validation:
    """Everything `validate` computed for one ride (the figures, and the runs for plots)."""

    figures: dict[str, Any]
    ride: RideSeries
    on_course: RideOnCourse
    course: Course
    runs: list[ForwardRun]
    plans: list[Any]


def ride_conditions(ride: RideSeries, wind_enu_mps: np.ndarray | None = None) -> Conditions:
    """The ride's mean air density, still or with a steady wind (ENU, where it blows TO)."""
    rho = float(np.mean(ride.rho_kgpm3))
    if wind_enu_mps is None:
        return Conditions(air_density_kgpm3=rho)
    speed_kmh, from_deg = wind_meteo(wind_enu_mps)
    return dataclasses.replace(Conditions.from_meteo(wind_kmh=speed_kmh, wind_from_deg=from_deg),
                               air_density_kgpm3=rho)


def validate_ride(ride: str | Path | RideSeries, course: Course, rider: Rider, *,
                  models: tuple[str, ...] = ("1d", "3d"), plan_models: tuple[str, ...] = (),
                  temperature_c: float | None = None, elevation: str = "auto",
                  cache_dir: Path = Path(".itt_cache")) -> Validation:
    """Physics check (the 1D model with the ride's power alone in still air and in the
    day's wind, then with the ride's braking and stops too; the 3D model in the day's
    wind with the ride's braking and stops; as `models` asks) and, for each of
    `plan_models`, the plan check (at the ride's air density, in the day's wind). A 3D
    replay that stalls is reported, not raised (`physics_3d`).

    The day's wind is fitted to the ride for this rider (`aero.fit_day_wind`): two
    numbers for the whole ride, a condition of the day like the air density, not a
    property of the rider. Without enough steady stretches only still air is run.

    `elevation`: the profile the replays climb. "course": the course's; "ride": the
    ride's own altitude laid on the course place by place, averaged over the passes of
    each place and smoothed (`ride_elevation`); "auto": "ride" when the course was
    fitted from this ride's file with its device altitude (the same readings, better
    placed), else "course" (also when the ride's profile is refused: `elevation` in the
    figures says why). The plan check always uses `course` (the plan's road).

    Raises:
        CalibrationError: the ride is unusable or does not lie on `course`, or the
            course's elevation disagrees with itself where it passes a place twice
            (`elevation_check`: a drifting altimeter's profile), or `elevation` is
            "ride" and the ride does not cover the course, or `elevation` is unknown.
        SolveError: a plan could not be set up (a plan that does not converge is
            checked anyway and says so: `converged: false`).
    """
    series = ride if isinstance(ride, RideSeries) else load_rides([ride], temperature_c)[0]
    check_course_elevation(course, series.source)
    on_course = ride_on_course(series, course)
    replayed, elevation_note = _replay_course(series, course, elevation)
    conditions = ride_conditions(series)
    wind_note: dict[str, Any] = {}
    try:
        wind = fit_day_wind(series, rider.mass_kg, rider.crr, rider.drag_area_m2,
                            rider.drivetrain_efficiency)
    except CalibrationError as err:
        wind_note = {"not_fitted": str(err)}
    else:
        speed_kmh, from_deg = wind_meteo(wind)
        wind_note = {"speed_kmh": round(speed_kmh, 1), "from_deg": round(from_deg, 0)}
    day = ride_conditions(series, wind) if "speed_kmh" in wind_note else conditions
    day_label = "day wind" if "speed_kmh" in wind_note else "still air"
    runs = []
    if "1d" in models:
        # The ride's power alone (still air, then the day's wind), then with the ride's
        # braking and stops: what each of the ride's inputs explains.
        runs.append(forward_1d(replayed, rider, on_course, conditions, ride_brakes=False))
        if "speed_kmh" in wind_note:
            runs.append(forward_1d(replayed, rider, on_course, day, day_label,
                                   ride_brakes=False))
        runs.append(forward_1d(replayed, rider, on_course, day, day_label))
    figures: dict[str, Any] = {
        "ride": series.source, "course": course.name, "rider": rider.name,
        "rider_values": _rider_values(rider),
        "matched_share": round(on_course.matched_share, 3),
        "covered_m": round(float(on_course.s_m[-1] - on_course.s_m[0]), 1),
        # The ride's speed x moving time over the course's length: a speed sensor (or a
        # course length) off by this scales every replay's finish by it.
        "speed_distance_ratio": round(float(np.sum(on_course.v_mps[:-1]
                                                   * on_course.moving_dt_s())
                                            / (on_course.s_m[-1] - on_course.s_m[0])), 4),
        "air_density_kgpm3": round(conditions.air_density_kgpm3, 4),
        "day_wind": wind_note,
        "elevation": elevation_note,
    }
    if "3d" in models:
        try:
            runs.append(forward_3d(replayed, rider, on_course, day, day_label))
        except CalibrationError as err:
            figures["physics_3d"] = str(err)
    grip = day.mu_y * GRAVITY_MPS2
    figures["physics"] = [physics_check(run, on_course, replayed, grip) for run in runs]
    plans = []
    if plan_models:
        from itt_planner.ocp.cache import load_or_solve  # noqa: PLC0415
        from itt_planner.ocp.course_settings import OcpSettings  # noqa: PLC0415  (CasADi OCP, lazy)

        figures["plans"] = []
        for model in plan_models:
            plan = load_or_solve(course, rider, day, OcpSettings(), model,
                                 cache_dir=cache_dir)
            if not plan.meta.get("success", False):
                log.warning("plan (%s) for %s did not converge: %s", model, course.name,
                            plan.solver_status)
            plans.append(plan)
            figures["plans"].append(plan_check(plan, on_course, course))
    return Validation(figures, series, on_course, course, runs, plans)


def _replay_course(series: RideSeries, course: Course, elevation: str
                   ) -> tuple[Course, dict[str, Any]]:
    """The course the physics replays run on, and which elevation it has (figures).

    Raises:
        CalibrationError: an unknown `elevation`, or "ride" on a ride that does not
            cover the course.
    """
    if elevation not in ("auto", "course", "ride"):
        raise CalibrationError(f"elevation {elevation!r}: expected auto, course or ride")
    if elevation == "course" or (elevation == "auto"
                                 and not is_ride_course(course, series.source)):
        return course, {"source": "course"}
    try:
        return ride_elevation(series, course)
    except CalibrationError as err:
        if elevation == "ride":
            raise
        # auto: the course's profile, and the JSON says why not the ride's.
        log.warning("validate: the course's elevation kept: %s", err)
        return course, {"source": "course", "ride_refused": str(err)}


def _rider_values(rider: Rider) -> dict[str, Any]:
    """The rider's fitted fields, for the report (what the validation was run with)."""
    names = ("mass_kg", "drag_area_m2", "crr", "critical_power_w", "w_prime_j",
             "drivetrain_efficiency", "max_lateral_accel_mps2")
    return {n: (round(v, 5) if isinstance(v, float) else v)
            for n in names if (v := getattr(rider, n, None)) is not None}


def holdout(rides: list[str | Path], courses: list[Course],
            options: CalibrationOptions = CalibrationOptions(),
            models: tuple[str, ...] = ("1d",)) -> dict[str, Any]:
    """Calibrate on all rides but one, validate (physics) on that one, for each ride.

    Raises:
        CalibrationError: fewer than two rides.
    """
    if len(rides) < 2:
        raise CalibrationError("--holdout needs at least two rides (fit on the others)")
    out: list[dict[str, Any]] = []
    for k, ride in enumerate(rides):
        train = [r for j, r in enumerate(rides) if j != k]
        try:
            fit = calibrate(train, options, courses=[c for j, c in enumerate(courses) if j != k])
            val = validate_ride(ride, courses[k], fit.rider, models=models,
                                temperature_c=options.temperature_c)
        except CalibrationError as err:
            out.append({"held_out": str(ride), "refused": str(err)})
            continue
        phys = val.figures["physics"][-1]  # the last run: the ride's inputs, the day's wind
        out.append({"held_out": str(ride), "trained_on": [str(r) for r in train],
                    "model": phys["model"], "conditions": phys["conditions"],
                    "cda_m2": round(fit.rider.drag_area_m2, 4),
                    "mass_kg": round(fit.rider.mass_kg, 1),
                    "refusals": fit.refusals, "warnings": fit.warnings,
                    **{k2: phys[k2] for k2 in ("finish_error_pct", "mae_kmh", "rmse_kmh",
                                               "bias_kmh", "share_within_2kmh",
                                               "noise_floor_kmh")}})
    return {"holdout": out}
