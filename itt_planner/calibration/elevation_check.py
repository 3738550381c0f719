"""Is an elevation profile consistent with itself? The test of places passed twice.

The power balance needs the climbing work, so CdA, crr and a replay of the ride's power
are only as good as the elevation. A barometric altimeter reads a change of the
weather's air pressure as a climb (1 hPa is ~8 m): over a long ride it can drift by tens
of metres, and a flat city ride then "climbs" 0.5 % where the rider coasts (a fitted
crr absorbs it; a replay stalls on it). The one test that needs no model: where the
ride (or course) passes the same place twice, within `SAME_PLACE_M` horizontally and
far apart in time or distance, the two heights must agree. A road over another (a
flyover, a bridge) is a few metres up, a jittery altimeter +-10 m (St John's: 16 m at
worst over 5628 pairs); beyond `MAX_DRIFT_M` at the same place the profile is not the
road's. The Shanghai ride ends 16 m from where it started, 85 m higher.

A profile without places passed twice is not tested (nothing to compare).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pymap3d
from scipy.spatial import cKDTree

from itt_planner.calibration.ride_data import CalibrationError, RideSeries
from itt_planner.course.geometry import Course
from itt_planner.logs.ride_import import MOVING_MPS

#: Two fixes this close horizontally are the same place (m).
SAME_PLACE_M = 10.0
#: Heights at the same place further apart than this: the profile drifted (m).
MAX_DRIFT_M = 30.0
#: A ride passes a place again only after this long (s); a course after this far (m).
_APART_S = 600.0
_APART_M = 500.0
#: Course points tested (every this many metres).
_COURSE_STEP_M = 5.0


@dataclass(frozen=True)
class Drift:
    """The worst disagreement between two passages of one place.

    Attributes:
        dz_m: height at the second passage minus the first.
        first, second: where (arc length, m) or when (s) the two passages were.
        pairs: how many pairs of passages were compared.
    """

    dz_m: float
    first: float
    second: float
    pairs: int


def worst_drift(x_m: np.ndarray, y_m: np.ndarray, z_m: np.ndarray, along: np.ndarray,
                apart: float) -> Drift | None:
    """The pair of points within `SAME_PLACE_M` of each other and at least `apart`
    along (`along`: time or arc length) whose heights differ most; None without pairs."""
    tree = cKDTree(np.column_stack([x_m, y_m]))
    pairs = tree.query_pairs(SAME_PLACE_M, output_type="ndarray")
    if len(pairs) == 0:
        return None
    i, j = pairs[:, 0], pairs[:, 1]
    far = np.abs(along[j] - along[i]) >= apart
    if not far.any():
        return None
    i, j = i[far], j[far]
    first_is_i = along[i] <= along[j]
    a, b = np.where(first_is_i, i, j), np.where(first_is_i, j, i)
    dz = z_m[b] - z_m[a]
    k = int(np.argmax(np.abs(dz)))
    return Drift(float(dz[k]), float(along[a[k]]), float(along[b[k]]), len(a))


def ride_altitude_drift(ride: RideSeries) -> Drift | None:
    """`worst_drift` of the ride's recorded altitude at the places it passed twice (moving
    fixes, at least `_APART_S` apart)."""
    moving = np.isfinite(ride.lat_deg) & np.isfinite(ride.lon_deg) & (ride.v_mps > MOVING_MPS)
    if moving.sum() < 2:
        return None
    lat, lon = ride.lat_deg[moving], ride.lon_deg[moving]
    # ENU about the first moving fix, as the calibration's other geometry (aero_design).
    x, y, _ = pymap3d.geodetic2enu(lat, lon, 0.0, lat[0], lon[0], 0.0)
    return worst_drift(x, y, ride.ele_m[moving], ride.t_s[moving], _APART_S)


def check_ride_altitude(ride: RideSeries) -> None:
    """Refuse a ride whose altitude disagrees with itself at a place passed twice.

    Raises:
        CalibrationError: naming the file, the height difference, and when.
    """
    drift = ride_altitude_drift(ride)
    if drift is not None and abs(drift.dz_m) > MAX_DRIFT_M:
        raise CalibrationError(
            f"{ride.source}: the altitude is not the road's: passing the same place at "
            f"{drift.first / 60:.0f} and {drift.second / 60:.0f} min, the record reads "
            f"{drift.dz_m:+.0f} m (more than {MAX_DRIFT_M:.0f} m; {drift.pairs} pairs of "
            "passages compared). A barometric altimeter drifts with the weather's pressure; "
            "the power balance would read that drift as climbing work")


def check_course_elevation(course: Course, source: str) -> None:
    """Refuse a course whose elevation disagrees with itself where it passes the same
    place twice (`source`: the file the course came from, for the message).

    Raises:
        CalibrationError: naming the file, the height difference, and where.
    """
    idx = np.arange(0, len(course.s_m), max(int(_COURSE_STEP_M / course.ds_m), 1))
    drift = worst_drift(course.x_m[idx], course.y_m[idx], course.z_m[idx], course.s_m[idx],
                        _APART_M)
    if drift is not None and abs(drift.dz_m) > MAX_DRIFT_M:
        raise CalibrationError(
            f"{source}: the elevation of course {course.name!r} is not the road's: it passes "
            f"the same place at km {drift.first / 1000:.1f} and km {drift.second / 1000:.1f} "
            f"{drift.dz_m:+.0f} m higher (more than {MAX_DRIFT_M:.0f} m). A replay of the "
            "ride's power would climb (or descend) that drift; give a --course with a "
            "right elevation")
