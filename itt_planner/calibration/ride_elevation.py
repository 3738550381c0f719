"""The ride's own altitude, place by place, as the elevation its replay climbs.

A replay's speed is set by energy: one metre of altitude wrong over a few hundred metres
is ~1 kJ per 100 kg, ~3.5 km/h at 10 m/s until drag relaxes it (~150 m). The course
fitted from a ride carries that ride's altitude through the course fit's spline, on its
own arc length; the replay places the ride's power and speed by `matching`. Here the
same altitude is laid on the course by the same matching (the mean of the samples in
each 1 m cell, interpolated between them) and:

- where the ride passes a place more than once (fixes of the course within
  `PASS_RADIUS_M`, at least `PASS_APART_M` apart along it: laps, out-and-back), the
  short-scale part of the profile (what a `PASS_LOWPASS_M` Gaussian mean leaves) is
  averaged over the passes; each pass keeps its own long-scale part, so an altimeter's
  drift between the passes (weather, warming) stays where it was (`elevation_check`
  judges it) and only the noise of the readings averages out. A pass more than
  `PASS_REJECT_M` away there is another road (a bridge) and is not averaged in;
- the result is smoothed by a Gaussian of `SMOOTHING_M` (sigma half of it): barometric
  altitude is quantised to 0.2 m and jitters by a few tenths, which a shorter window
  reads as grade (St John's, one pass: 10 m gives 1.98 km/h of replay MAE, 60 m 1.73).

Measured on the real rides (bench/bench_replay_error.py, 1D, day wind, the ride's
braking and stops, rider calibrated on the same ride), speed MAE on the course's
profile -> here at 40 / 60 / 80 m: St John's 1.91 -> 1.69 / 1.64 / 1.61 km/h (two laps
averaged), Ardennes 2.25 -> 2.15 / 2.16 / 2.16, the Zwift ride 1.23 -> 0.62 / 0.70 / 0.82
(the game's altitude is exact: less smoothing is better there).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.ndimage import gaussian_filter1d, maximum_filter1d
from scipy.spatial import cKDTree

from itt_planner.calibration.matching import course_progress
from itt_planner.calibration.ride_data import CalibrationError, RideSeries
from itt_planner.course.geometry import Course
from itt_planner.course.track_files import file_sha256

#: Gaussian window of the replay's profile (m; sigma is half of it): the course fit's
#: nominal altitude length (`FitSettings.altitude_scale_m`), not tuned to the rides.
SMOOTHING_M = 60.0
#: Fixes of the course this close are one place (m) ...
PASS_RADIUS_M = 8.0
#: ... when at least this far apart along the course (m).
PASS_APART_M = 500.0
#: Scale of each pass's own part of the profile (m; Gaussian sigma half of it).
PASS_LOWPASS_M = 1000.0
#: Passes whose short-scale altitude differs more than this are different roads (m).
PASS_REJECT_M = 3.0
#: Neighbours looked at per course point (1 m grid: ~17 per pass within 8 m).
_NEIGHBOURS = 96
#: Course points per neighbour query (bounds the memory of `pass_readings`).
_CHUNK = 8192
#: Share of the course the ride must cover for its altitude to replace the course's.
MIN_COVERED = 0.9


def is_ride_course(course: Course, ride_path: str | Path) -> bool:
    """True when `course` was fitted from the file `ride_path` with its device altitude
    (the course's elevation is this ride's altitude, re-profiled here)."""
    path = Path(ride_path)
    if not course.source_sha256 or not path.is_file():
        return False
    source = course.build.get("elevation", {}).get("source")
    return source == "device" and course.source_sha256 == file_sha256(path)


def altitude_on_course(ride: RideSeries, course: Course) -> tuple[np.ndarray, float]:
    """The ride's altitude per course grid point (the mean of the samples matched to
    each cell, interpolated between cells) and the share of cells within 50 m of one.

    Raises:
        CalibrationError: no sample lies on the course.
    """
    s = course_progress(course, ride.lat_deg, ride.lon_deg, ride.t_s)
    ok = np.isfinite(s)
    if not ok.any():
        raise CalibrationError(f"{ride.source}: no sample lies on course {course.name!r}")
    cell = np.clip(np.round(s[ok] / course.ds_m).astype(int), 0, len(course.s_m) - 1)
    total = np.bincount(cell, ride.ele_m[ok], len(course.s_m))
    count = np.bincount(cell, minlength=len(course.s_m))
    have = count > 0
    z: np.ndarray = np.interp(course.s_m, course.s_m[have], total[have] / count[have])
    near = maximum_filter1d(have.astype(np.uint8), size=2 * int(50.0 / course.ds_m) + 1) > 0
    return z, float(np.mean(near))


@dataclass(frozen=True, eq=False)
class PassReadings:
    """A profile split by place (module docstring), per course grid point.

    Attributes:
        low: the pass's own long-scale part (Gaussian mean over `PASS_LOWPASS_M`).
        short: the pass's own short-scale part (`z - low`).
        other_short: the mean short-scale reading of the OTHER passes of the place (0
            where there is none).
        other_passes: how many other passes (grid points within the radius over this
            pass's own count: each pass brings about as many); 0 where none.
    """

    low: np.ndarray
    short: np.ndarray
    other_short: np.ndarray
    other_passes: np.ndarray

    def averaged(self) -> np.ndarray:
        """The profile with its short-scale part averaged over every pass."""
        mean: np.ndarray = self.low + ((self.short + self.other_passes * self.other_short)
                                       / (1.0 + self.other_passes))
        return mean

    @property
    def passed_share(self) -> float:
        """Share of the course passed more than once."""
        return float(np.mean(self.other_passes > 0))


def pass_readings(course: Course, z: np.ndarray) -> PassReadings:
    """`z` split into each pass's long-scale part and the short-scale readings of this
    pass and of the others at the same place (module docstring)."""
    low = gaussian_filter1d(z, PASS_LOWPASS_M / 2.0 / course.ds_m, mode="nearest")
    short = z - low
    xy = np.c_[course.x_m, course.y_m]
    tree = cKDTree(xy)
    other_short = np.zeros(len(z))
    passes = np.zeros(len(z))
    # In chunks: the neighbour table of a 100 km course at once is ~100 MB per array.
    for lo in range(0, len(z), _CHUNK):
        at = np.arange(lo, min(lo + _CHUNK, len(z)))
        dist, idx = tree.query(xy[at], k=min(_NEIGHBOURS, len(z)),
                               distance_upper_bound=PASS_RADIUS_M)
        found = np.isfinite(dist)
        idx = np.where(found, idx, 0)
        apart = np.abs(course.s_m[idx] - course.s_m[at, None]) >= PASS_APART_M
        other = found & apart & (np.abs(short[idx] - short[at, None]) <= PASS_REJECT_M)
        n_other = other.sum(axis=1)
        other_short[at] = (short[idx] * other).sum(axis=1) / np.maximum(n_other, 1)
        passes[at] = n_other / np.maximum((found & ~apart).sum(axis=1), 1)
    return PassReadings(low, short, other_short, passes)


def with_profile(course: Course, z_m: np.ndarray) -> Course:
    """`course` with the altitude `z_m` on its grid and the slope that follows from it."""
    return dataclasses.replace(course, z_m=z_m, beta_rad=np.arctan(np.gradient(z_m, course.s_m)))


def ride_elevation(ride: RideSeries, course: Course, smoothing_m: float = SMOOTHING_M
                   ) -> tuple[Course, dict[str, Any]]:
    """`course` with its elevation (z and slope) from the ride's own altitude (module
    docstring), and what was done (for the figures).

    Raises:
        CalibrationError: the ride covers less than `MIN_COVERED` of the course (its
            altitude cannot replace the course's), or no sample lies on it.
    """
    z, covered = altitude_on_course(ride, course)
    if covered < MIN_COVERED:
        raise CalibrationError(f"{ride.source}: the ride's altitude covers {100 * covered:.0f} % "
                               f"of course {course.name!r} (at least {100 * MIN_COVERED:.0f} % "
                               "needed to replay on it)")
    readings = pass_readings(course, z)
    smooth = gaussian_filter1d(readings.averaged(), smoothing_m / 2.0 / course.ds_m,
                               mode="nearest")
    new = with_profile(course, smooth)
    report = {"source": "ride", "smoothing_m": smoothing_m,
              "passed_more_than_once_share": round(readings.passed_share, 3),
              "rms_vs_course_m": round(float(np.sqrt(np.mean((smooth - course.z_m) ** 2))), 2)}
    return new, report
