"""A ride laid on its course: power, speed and moving time as functions of arc length.

Validation compares models and plans with the ride place by place, so the ride is
expressed on a uniform grid of the course (`step_m`): the power the rider put out
there, the speed (smoothed over 5 s), the raw GPS speed, and the moving time it took to
get there (stops and pauses removed: the models never stop at a junction), and the
time it stood or paused (where a replay restarts from the ride's state).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np

from itt_planner.calibration.matching import course_progress
from itt_planner.calibration.ride_data import CalibrationError, RideSeries, smooth
from itt_planner.course.geometry import Course
from itt_planner.logs.ride_import import MOVING_MPS
from itt_planner.units import MPS_TO_KMH

#: Window of the smoothed ride speed the models are compared with (samples, 1 Hz).
SMOOTH_SAMPLES = 5


@dataclass(frozen=True, eq=False)
class RideOnCourse:
    """The ride on a uniform grid `s_m` of the course (from the first to the last matched
    position)."""

    s_m: np.ndarray
    power_w: np.ndarray
    v_mps: np.ndarray
    v_raw_gps_mps: np.ndarray
    t_moving_s: np.ndarray
    matched_share: float
    t_stopped_s: np.ndarray

    def moving_dt_s(self) -> np.ndarray:
        """The ride's moving time over each grid interval (0 where it was not seen
        moving: a recording gap it crossed)."""
        return np.diff(self.t_moving_s)

    def stopped_dt_s(self) -> np.ndarray:
        """Time the ride stood (or the record paused) within each grid interval."""
        return np.diff(self.t_stopped_s)

    @property
    def moving_time_s(self) -> float:
        return float(self.t_moving_s[-1] - self.t_moving_s[0])

    def noise_floor_kmh(self) -> float:
        """MAE of the raw GPS speed against the smoothed ride speed (km/h): no model can
        be judged closer to the ride than its own sensors agree."""
        good = np.isfinite(self.v_raw_gps_mps)
        return float(MPS_TO_KMH * np.mean(np.abs(self.v_raw_gps_mps[good] - self.v_mps[good])))


def ride_on_course(ride: RideSeries, course: Course, step_m: float = 5.0) -> RideOnCourse:
    """Match the ride to `course` and resample it on a `step_m` grid.

    Raises:
        CalibrationError: less than half of the moving samples lie on the course (wrong
            --course), or the matched stretch is shorter than 1 km.
    """
    s = course_progress(course, ride.lat_deg, ride.lon_deg, ride.t_s)
    moving = ride.v_mps > MOVING_MPS
    matched = np.isfinite(s) & moving
    share = float(matched.sum() / max(moving.sum(), 1))
    if share < 0.5:
        raise CalibrationError(f"{ride.source}: only {100 * share:.0f} % of the moving samples "
                               f"lie on course {course.name!r}: wrong --course?")
    idx = np.flatnonzero(matched)
    s0, s1 = float(s[idx[0]]), float(s[idx[-1]])
    if s1 - s0 < 1000.0:
        raise CalibrationError(f"{ride.source}: the ride covers only {s1 - s0:.0f} m of course "
                               f"{course.name!r}")
    # Moving time: intervals inside one block with the rider moving.
    dt = np.diff(ride.t_s)
    keep = (np.diff(ride.block) == 0) & (ride.v_mps[1:] > MOVING_MPS)
    t_moving = np.concatenate([[0.0], np.cumsum(np.where(keep, dt, 0.0))])
    t_stopped = ride.t_s - ride.t_s[0] - t_moving  # standing, and recording gaps
    v_smooth = smooth(ride.v_mps, ride.block, SMOOTH_SAMPLES)
    grid = np.arange(s0, s1, step_m)
    # Progress is monotone in the matched samples; repeated s (a stop) keep the first.
    ss = s[idx]
    first = np.concatenate([[True], np.diff(ss) > 0])
    at = idx[first]
    sk = s[at]
    return RideOnCourse(
        s_m=grid, power_w=_interval_mean(grid, s[idx], ride.power_w[idx]),
        v_mps=np.interp(grid, sk, v_smooth[at]),
        v_raw_gps_mps=np.interp(grid, sk, np.nan_to_num(ride.gps_speed_mps[at], nan=np.nan)),
        t_moving_s=np.interp(grid, sk, t_moving[at]), matched_share=share,
        t_stopped_s=np.interp(grid, sk, t_stopped[at]),
    )


def _interval_mean(grid: np.ndarray, s: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Mean of `values` over the samples whose `s` falls in each grid cell, interpolated
    over cells without a sample (1 Hz samples are ~10 m apart at speed)."""
    cell = np.clip(np.searchsorted(grid, s, side="right") - 1, 0, len(grid) - 1)
    total = np.bincount(cell, weights=values, minlength=len(grid))
    count = np.bincount(cell, minlength=len(grid))
    have = count > 0
    return cast(np.ndarray, np.interp(grid, grid[have], total[have] / count[have]))
