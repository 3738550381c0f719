"""The ride's own altitude as the replay's elevation: passes averaged, drift kept, refusals."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d
from support.calibration_ride import calibration_course
from support.real_data import data_path

from itt_planner.calibration import CalibrationError
from itt_planner.calibration.calibrate import load_rides
from itt_planner.calibration.ride_data import RideSeries
from itt_planner.calibration.ride_elevation import (
    PASS_LOWPASS_M,
    is_ride_course,
    pass_readings,
    ride_elevation,
)
from itt_planner.calibration.validate import validate_ride
from itt_planner.course.geometry import Course, GeoOrigin
from itt_planner.model.rider import PRESETS

ST_JOHNS = "rides/edge810_vector_stjohns_2013.fit"
LAP_M = 2 * np.pi * 500.0


def two_laps(z_of_angle: Callable[[np.ndarray], np.ndarray]) -> Course:
    """Two laps of a 500 m-radius circle (the second rides the first's road), altitude
    `z_of_angle` of the place."""
    angle = np.linspace(0.0, 4.0 * np.pi, 20001)
    return Course.from_centerline("two-laps", 500.0 * np.cos(angle), 500.0 * np.sin(angle),
                                  z_of_angle(angle), origin=GeoOrigin(45.0, 10.0, 100.0))


def head(ride: RideSeries, share: float) -> RideSeries:
    """The ride's first `share` of its clock."""
    n = int(np.searchsorted(ride.t_s, share * ride.t_s[-1]))
    names = ("t_s", "v_mps", "power_w", "ele_m", "dist_m", "rho_kgpm3", "block", "lat_deg",
             "lon_deg", "gps_speed_mps")
    return dataclasses.replace(ride, **{k: getattr(ride, k)[:n] for k in names})


def short(z: np.ndarray, course: Course) -> np.ndarray:
    return z - gaussian_filter1d(z, PASS_LOWPASS_M / 2.0 / course.ds_m, mode="nearest")


def test_passes_average_the_noise_and_keep_each_lap_drift() -> None:
    """Two laps read the same bumps with independent noise and the second 3 m higher
    (an altimeter drifting): averaged, the short-scale error falls by ~1/sqrt(2) and the
    second lap keeps its 3 m (the drift is each pass's own, `elevation_check` judges it)."""
    truth = two_laps(lambda a: 2.0 * np.sin(12.0 * a))  # bumps of 262 m, same each lap
    rng = np.random.default_rng(7)
    # Noise of the altimeter, correlated over ~20 m like a smoothed 1 Hz reading.
    noise = gaussian_filter1d(rng.normal(0.0, 3.0, len(truth.s_m)), 10.0)
    drift = np.where(truth.s_m > LAP_M, 3.0, 0.0)
    drift = gaussian_filter1d(drift, 200.0)
    read = truth.z_m + noise + drift
    readings = pass_readings(truth, read)
    assert readings.passed_share > 0.95
    inner = (truth.s_m > 1500.0) & (truth.s_m < truth.length_m - 1500.0)
    single = np.std((short(read, truth) - short(truth.z_m, truth))[inner])
    averaged = np.std((short(readings.averaged(), truth) - short(truth.z_m, truth))[inner])
    assert averaged < 0.8 * single, (averaged, single)
    lap2 = (truth.s_m > LAP_M + 1500.0) & (truth.s_m < 2 * LAP_M - 1500.0)
    assert np.mean((readings.averaged() - truth.z_m)[lap2]) == pytest.approx(3.0, abs=0.5)


def test_another_road_at_the_same_place_is_not_averaged() -> None:
    """A second lap 10 m below the first at a crossing bump (a bridge over the road
    shows as a short-scale difference beyond 3 m) is not read as the same place."""
    bridge = two_laps(lambda a: np.where((a > 2 * np.pi + 1.0) & (a < 2 * np.pi + 1.3),
                                         -10.0 * np.sin((a - 2 * np.pi - 1.0) / 0.3 * np.pi),
                                         0.0))
    readings = pass_readings(bridge, bridge.z_m)
    deep = np.argmin(bridge.z_m)
    assert bridge.z_m[deep] < -9.0
    assert readings.averaged()[deep] == pytest.approx(bridge.z_m[deep], abs=0.5)


def test_another_course_keeps_its_elevation() -> None:
    """Only a course fitted from the ride's own file takes the ride's altitude on
    `auto`; a ride nowhere on a course has no altitude to give it."""
    path = data_path(ST_JOHNS)
    assert not is_ride_course(calibration_course(), path)
    with pytest.raises(CalibrationError, match="no sample lies on"):
        ride_elevation(load_rides([path], None)[0], two_laps(lambda a: 0.0 * a))


def test_st_johns_ride_elevation(real_course: Callable[[str], Course]) -> None:
    """St John's course was fitted from the ride: `auto` takes its altitude, both laps
    averaged; the profile stays within ~1 m of the course's; a quarter of the ride is
    refused (it covers too little of the course)."""
    path = data_path(ST_JOHNS)
    course = real_course(ST_JOHNS)
    assert is_ride_course(course, path)
    ride = load_rides([path], None)[0]
    replay, note = ride_elevation(ride, course)
    assert note["source"] == "ride" and note["passed_more_than_once_share"] > 0.95
    assert 0.1 < note["rms_vs_course_m"] < 1.5
    assert np.all(np.abs(np.tan(replay.beta_rad)) < 0.2)
    with pytest.raises(CalibrationError, match="covers"):
        ride_elevation(head(ride, 0.25), course)


def test_auto_keeps_the_course_profile_when_the_ride_is_refused(
        real_course: Callable[[str], Course]) -> None:
    """`validate` on its own course's file with a quarter of the ride: the ride's altitude
    covers too little of the course, so `auto` replays on the course's profile and says
    why (a fallback is reported, not silent); `ride` asked for is refused."""
    path = data_path(ST_JOHNS)
    course = real_course(ST_JOHNS)
    part = head(load_rides([path], None)[0], 0.25)
    figures = validate_ride(part, course, PRESETS["paper"], models=("1d",)).figures
    assert figures["elevation"]["source"] == "course"
    assert "covers" in figures["elevation"]["ride_refused"]
    with pytest.raises(CalibrationError, match="covers"):
        validate_ride(part, course, PRESETS["paper"], models=("1d",), elevation="ride")
