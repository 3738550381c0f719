"""Physics check figures of what a replay cannot model: corners ridden beyond grip."""

from __future__ import annotations

import numpy as np
import pytest

from itt_planner.calibration.forward import ForwardRun
from itt_planner.calibration.physics_check import (
    BEYOND_GRIP_AFTER_M,
    physics_check,
    unmodelled_lines,
)
from itt_planner.calibration.ride_on_course import RideOnCourse
from itt_planner.course.builder import build_course
from itt_planner.course.geometry import Course
from itt_planner.model.conditions import GRAVITY_MPS2


@pytest.fixture(scope="module")
def course() -> Course:
    spec = {"name": "one hairpin", "segments": [
        {"type": "straight", "length_m": 1000},
        {"type": "arc", "angle_deg": 180, "radius_m": 10, "direction": "left"},
        {"type": "straight", "length_m": 1500}],
        "origin": {"lat_deg": 45.0, "lon_deg": 10.0, "alt_m": 200.0}}
    return build_course(spec, source="tests/calibration/test_physics_check.py")


def _ride(course: Course, speed_mps: float) -> RideOnCourse:
    s = np.arange(0.0, course.length_m - 5.0, 5.0)
    v = np.full(len(s), speed_mps)
    t = s / speed_mps
    return RideOnCourse(s_m=s, power_w=np.full(len(s), 200.0), v_mps=v, v_raw_gps_mps=v,
                        t_moving_s=t, matched_share=1.0, t_stopped_s=np.zeros(len(s)))


def test_corner_beyond_grip_reported_with_its_time(course: Course) -> None:
    """A game's rider rounds the 10 m hairpin at 54 km/h (22.5 m/s^2, 2.3 g): the corner is
    named, the 12 s a grip-limited model lost around it (slow from 50 m before to 200 m
    after) are counted there, and outside it the model finishes with the ride. At 25 km/h
    (4.8 m/s^2) nothing is reported."""
    (corner,) = course.corners
    ride = _ride(course, 15.0)
    slow = (ride.s_m > corner.entry_s_m - 50.0) & (ride.s_m <= corner.exit_s_m + 200.0)
    dt = np.diff(ride.t_moving_s) * np.where(slow[1:], 2.0, 1.0)
    t = np.concatenate([[0.0], np.cumsum(dt)])
    run = ForwardRun("3d", "test", ride.s_m, np.where(slow, 7.5, 15.0), t)
    lost = float(t[-1] - ride.t_moving_s[-1])
    figures = physics_check(run, ride, course, grip_mps2=GRAVITY_MPS2)
    (named,) = figures["corners_beyond_grip"]
    assert named["radius_m"] == pytest.approx(10.0, rel=0.05)
    assert named["ride_lateral_accel_mps2"] == pytest.approx(22.5, rel=0.05)
    assert figures["beyond_grip"]["model_minus_ride_s"] == pytest.approx(lost, abs=0.1)
    assert figures["beyond_grip"]["zone_m"] >= BEYOND_GRIP_AFTER_M
    assert figures["outside_beyond_grip"]["finish_error_pct"] == pytest.approx(0.0, abs=1e-3)
    assert figures["finish_error_pct"] > 5.0
    assert any("beyond the road's grip" in line for line in unmodelled_lines(figures))
    calm = _ride(course, 7.0)
    same = ForwardRun("3d", "test", calm.s_m, calm.v_mps, calm.t_moving_s)
    assert "corners_beyond_grip" not in physics_check(same, calm, course)
    assert unmodelled_lines(physics_check(same, calm, course)) == []
