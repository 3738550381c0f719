"""The elevation's self-consistency at places passed twice: a drifting profile refused."""

from __future__ import annotations

import pytest
from support.real_data import data_path

from itt_planner.calibration import CalibrationError
from itt_planner.calibration.calibrate import load_rides
from itt_planner.calibration.elevation_check import (
    check_course_elevation,
    check_ride_altitude,
    ride_altitude_drift,
)
from itt_planner.course.builder import build_course
from itt_planner.course.geometry import Course


def _two_laps(grade: float) -> Course:
    """Two laps of a 400 m x 100 m oval, climbing `grade` all the way (a closed road cannot:
    the second lap is `grade` x one lap higher at every place)."""
    lap = [{"type": "straight", "length_m": 400, "grade": grade},
           {"type": "arc", "angle_deg": 180, "radius_m": 50, "direction": "left", "grade": grade},
           {"type": "straight", "length_m": 400, "grade": grade},
           {"type": "arc", "angle_deg": 180, "radius_m": 50, "direction": "left", "grade": grade}]
    return build_course({"name": f"oval {grade}", "segments": lap + lap,
                         "origin": {"lat_deg": 45.0, "lon_deg": 10.0, "alt_m": 100.0}},
                        source="tests/calibration/test_elevation_check.py")


def test_course_passing_a_place_higher_is_refused() -> None:
    """A flat oval passes; the same oval climbing 4 % everywhere ends where it started
    89 m higher (two laps of 1114 m), beyond the limit: refused, naming the file and the
    figure. At 1 % (22 m, within what a jittery altimeter does) it passes."""
    check_course_elevation(_two_laps(0.0), "flat.gpx")
    check_course_elevation(_two_laps(0.01), "one_pct.gpx")
    with pytest.raises(CalibrationError, match=r"drift.gpx: the elevation .* \+89 m higher"):
        check_course_elevation(_two_laps(0.04), "drift.gpx")


def test_real_ride_with_a_drifting_altitude() -> None:
    """The Shanghai ELEMNT ride ends 16 m from its start 85 m higher (its altimeter drifted
    in a flat city): refused, naming the file and the figure. (St John's, a jittery
    altimeter at 16 m at worst, passes: its calibration and validation in test_validate
    run these checks.)"""
    # The temperature given: the FIT file is parsed once (the altitude does not need it).
    (shanghai,) = load_rides([data_path("rides/elemnt_shanghai_2019_stopgo.fit")], 15.0)
    drift = ride_altitude_drift(shanghai)
    assert drift is not None and drift.dz_m > 80.0 and drift.pairs > 1000
    assert drift.second - drift.first >= 600.0
    with pytest.raises(CalibrationError, match=r"elemnt_shanghai.*\+85 m"):
        check_ride_altitude(shanghai)
