"""The ride's braking and stops as replay inputs: known truth from the 1D model itself.

A ride made by the project's own 1D model (RK4 in space) with a known braking zone and a
stop: the braking read back from the ride is the truth, and the replay with it finishes
where the ride did; without it, the replay is fast through the braking zone.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from itt_planner.calibration.forward import forward_1d
from itt_planner.calibration.physics_check import physics_check
from itt_planner.calibration.ride_inputs import (
    BRAKE_MARGIN_MPS2,
    LAUNCH_MPS,
    STOP_MIN_S,
    ride_inputs,
)
from itt_planner.calibration.ride_on_course import RideOnCourse
from itt_planner.calibration.shelter import SHELTER_MIN_M, SHELTER_SHARE
from itt_planner.course.builder import build_course
from itt_planner.course.geometry import Course
from itt_planner.model.conditions import Conditions
from itt_planner.model.dynamics import build_1d, rk4_step
from itt_planner.model.params import ModelParams
from itt_planner.model.rider import PRESETS

RIDER = PRESETS["paper"]
#: The truth's braking command and where (m), on a 6 % descent.
BRAKE_W_N, BRAKE_FROM_M, BRAKE_TO_M = -0.15, 2300.0, 2400.0


@pytest.fixture(scope="module")
def course() -> Course:
    spec = {"name": "brake-test", "segments": [
        {"type": "straight", "length_m": 1500, "grade_pct": 0},
        {"type": "straight", "length_m": 1500, "grade_pct": -6},
        {"type": "straight", "length_m": 1000, "grade_pct": 0}],
        "origin": {"lat_deg": 45.0, "lon_deg": 10.0, "alt_m": 200.0}}
    return build_course(spec, source="tests/calibration/test_ride_inputs.py")


def _truth_ride(course: Course, stop_at_m: float | None = None) -> RideOnCourse:
    """The 1D model's own ride on a 5 m grid: 250 W, coasting with the brakes on over the
    braking zone; with `stop_at_m`, a 30 s stop there and a restart at 1 m/s."""
    model = build_1d()
    step = rk4_step(model, 2)
    par = ModelParams(RIDER, Conditions()).vector()
    s = np.arange(0.0, course.length_m - 5.0, 5.0)
    power = np.full(len(s), 250.0)
    braking = (s >= BRAKE_FROM_M) & (s < BRAKE_TO_M)
    power[braking] = 0.0
    v, t, stopped = np.empty(len(s)), np.zeros(len(s)), np.zeros(len(s))
    x = np.array([8.0, 0.0, 1.0])
    v[0] = x[0]
    for k in range(len(s) - 1):
        x[1] = BRAKE_W_N if braking[k] else power[k] / RIDER.max_power_w
        road = [0.0, float(course.at("beta_rad", 0.5 * (s[k] + s[k + 1]))), 0.0, 5.0]
        xf, dt, _ = step(x, 0.0, road, par)
        x = np.asarray(xf).ravel()
        stopped[k + 1] = stopped[k]
        if stop_at_m is not None and s[k] <= stop_at_m < s[k + 1]:
            x[0], stopped[k + 1] = 1.0, stopped[k] + 30.0
        v[k + 1], t[k + 1] = x[0], t[k] + float(dt)
    return RideOnCourse(s_m=s, power_w=power, v_mps=v, v_raw_gps_mps=v, t_moving_s=t,
                        matched_share=1.0, t_stopped_s=stopped)


def test_braking_read_back_from_the_ride(course: Course) -> None:
    """The braking command inferred from the ride is the truth's, where the truth braked,
    and nothing elsewhere (the margin keeps pedalling and coasting out)."""
    ride = _truth_ride(course)
    inputs = ride_inputs(build_1d(), course, RIDER, ride, Conditions())
    mid = 0.5 * (ride.s_m[1:] + ride.s_m[:-1])
    zone = (mid > BRAKE_FROM_M + 5) & (mid < BRAKE_TO_M - 5)
    assert inputs.brake_w_n[zone] == pytest.approx(BRAKE_W_N, rel=0.03)
    outside = (mid < BRAKE_FROM_M - 5) | (mid > BRAKE_TO_M + 5)
    assert not inputs.brake_w_n[outside].any()
    assert not inputs.stop.any() and not inputs.unseen.any()
    assert inputs.summary(ride)["braking_m"] == pytest.approx(BRAKE_TO_M - BRAKE_FROM_M, abs=10)
    assert 0 < BRAKE_MARGIN_MPS2 < abs(BRAKE_W_N) * 9.81


def test_replay_with_the_ride_braking_finishes_with_the_ride(course: Course) -> None:
    """Replayed with the inferred braking the model finishes with its own ride (< 0.1 %);
    with the power alone it rolls through the braking zone and arrives early."""
    ride = _truth_ride(course)
    real = ride.moving_time_s
    braked = forward_1d(course, RIDER, ride, ride_brakes=True)
    power_only = forward_1d(course, RIDER, ride, ride_brakes=False)
    assert braked.finish_time_s == pytest.approx(real, rel=1e-3)
    assert power_only.finish_time_s < real - 2.0
    assert np.max(np.abs(braked.v_mps - ride.v_mps)) < 0.1
    assert braked.ride_inputs is not None and braked.ride_inputs["stops"] == 0


def test_stop_restarts_from_the_ride_state(course: Course) -> None:
    """After a stop the replay carries nothing of its own speed through it: it restarts
    at the ride's speed, takes the ride's own figures while launching below the launch
    speed, and the stop's standing time counts for neither."""
    stop_at = 1000.0
    ride = _truth_ride(course, stop_at_m=stop_at)
    inputs = ride_inputs(build_1d(), course, RIDER, ride, Conditions())
    k = int(np.flatnonzero(inputs.stop)[0])
    assert ride.s_m[k] <= stop_at < ride.s_m[k + 1]
    assert ride.stopped_dt_s()[k] >= STOP_MIN_S
    run = forward_1d(course, RIDER, ride)
    assert run.v_mps[k + 1] == pytest.approx(ride.v_mps[k + 1])
    launch = np.flatnonzero(inputs.launch)
    assert launch.size and launch[0] == k + 1 and np.all(ride.v_mps[launch] < LAUNCH_MPS)
    assert run.finish_time_s == pytest.approx(ride.moving_time_s, rel=1e-3)
    assert run.ride_inputs is not None and run.ride_inputs["stops"] == 1


def test_unexplained_power_is_what_the_model_lacks(course: Course) -> None:
    """The model's own ride leaves no power unexplained; replayed by a rider with 20 % more
    drag, the ride got the missing drag power (0.2 x 1/2 rho CdA v^3) from outside the
    model, and the figure says so (over the braking-free 500 m windows)."""
    ride = _truth_ride(course)
    own = ride_inputs(build_1d(), course, RIDER, ride, Conditions()).summary(ride)
    assert own["unexplained_windows"] >= 5
    assert abs(own["unexplained_mean_w"]) < 0.5 and own["unexplained_sd_w"] < 0.5
    draggy = dataclasses.replace(RIDER, drag_area_m2=1.2 * RIDER.drag_area_m2)
    inputs = ride_inputs(build_1d(), course, draggy, ride, Conditions())
    v = 0.5 * (ride.v_mps[1:] + ride.v_mps[:-1])
    missing = 0.2 * 0.5 * Conditions().air_density_kgpm3 * RIDER.drag_area_m2 * v ** 3
    used = np.isfinite(inputs.unexplained_w)
    assert np.average(inputs.unexplained_w[used], weights=1 / v[used]) == pytest.approx(
        np.average(missing[used], weights=1 / v[used]), rel=0.05)
    assert inputs.summary(ride)["unexplained_mean_w"] > 10.0


def test_braking_only_down_to_the_ride_speed(course: Course) -> None:
    """A rider brakes for a speed: a replay slower than the ride where the ride braked
    coasts instead of braking further below it (the braking is counted as not needed),
    and one faster than the ride brakes for the ride's speed, with at most the ride's
    command (issue 15: the 1D replay braked by place, however slow it already was)."""
    ride = _truth_ride(course)
    mid = 0.5 * (ride.s_m[1:] + ride.s_m[:-1])
    zone = np.flatnonzero((mid > BRAKE_FROM_M) & (mid < BRAKE_TO_M))
    slower = dataclasses.replace(RIDER, drag_area_m2=1.5 * RIDER.drag_area_m2)
    run = forward_1d(course, slower, ride)
    assert run.ride_inputs is not None and run.ride_inputs["braking_not_needed_m"] > 0
    assert run.v_mps[zone[0]] < ride.v_mps[zone[0]]
    # Never below both the ride's speed and its own coasting (the power-only replay: the
    # ride's power is 0 over the zone, and both replays are one before it).
    coasting = forward_1d(course, slower, ride, ride_brakes=False)
    assert coasting.v_mps[zone[0]] == pytest.approx(run.v_mps[zone[0]])
    floor = np.minimum(ride.v_mps[zone + 1], coasting.v_mps[zone + 1])
    assert np.all(run.v_mps[zone + 1] >= floor - 1e-6)
    faster = dataclasses.replace(RIDER, drag_area_m2=0.8 * RIDER.drag_area_m2)
    fast = forward_1d(course, faster, ride)
    assert fast.v_mps[zone[0]] > ride.v_mps[zone[0]]
    # Braked toward the ride's speed, never below it.
    assert np.all(fast.v_mps[zone + 1] >= ride.v_mps[zone + 1] - 1e-3)
    power_only = forward_1d(course, faster, ride, ride_brakes=False)
    assert fast.v_mps[zone[-1] + 1] < power_only.v_mps[zone[-1] + 1] - 1.0


def test_sheltered_stretch_found_and_reported(course: Course) -> None:
    """The model's own ride, recorded with 130 W less than it rode at over 1000 m of the
    flat (the help a wheel to follow gives): that stretch, and only it, is sheltered; the
    replay (which rides it solo with the recorded power) loses its time there, and
    outside it finishes with the ride."""
    truth = _truth_ride(course)
    help_zone = (truth.s_m >= 500.0) & (truth.s_m < 1500.0)
    ride = dataclasses.replace(truth, power_w=np.where(help_zone, truth.power_w - 130.0,
                                                      truth.power_w))
    run = forward_1d(course, RIDER, ride)
    assert run.ride_inputs is not None and run.sheltered is not None
    assert run.ride_inputs["sheltered_stretches"] == 1
    (stretch,) = run.ride_inputs["sheltered"]
    assert (stretch["from_m"], stretch["length_m"]) == (500.0, 1000.0)
    assert stretch["length_m"] >= SHELTER_MIN_M and stretch["drag_share_unpaid"] > SHELTER_SHARE
    assert stretch["unexplained_w"] == pytest.approx(130.0, rel=0.1)
    figures = physics_check(run, ride, course)
    (lost,) = figures["sheltered_time_lost"]
    assert lost["model_minus_ride_s"] > 5.0
    outside = figures["outside_sheltered"]
    assert abs(outside["finish_error_pct"]) < abs(figures["finish_error_pct"]) / 3
    # The model's own ride, unchanged, has none.
    clean = forward_1d(course, RIDER, truth)
    assert clean.ride_inputs is not None and clean.ride_inputs["sheltered_stretches"] == 0
    assert "outside_sheltered" not in physics_check(clean, truth, course)
