"""Where on a course each sample of a ride was: monotone nearest-point matching.

A ride's GPS fixes are projected onto the course's 1 m centre-line grid, searching only
ahead of the previous match (a road that crosses itself or comes back alongside must
not pull the rider back or forward by kilometres); the window grows with the time
since the last fix. Fixes farther than `max_offset_m` from the road are left unmatched
(NaN): the rider was off the course (warm-up, the ride home).
"""

from __future__ import annotations

import numpy as np

from itt_planner.course.geometry import Course

#: Fastest plausible progress along the course between fixes (m/s) and slack (m).
_V_MAX_MPS = 30.0
_SLACK_M = 30.0


def course_progress(course: Course, lat_deg: np.ndarray, lon_deg: np.ndarray,
                    t_s: np.ndarray, max_offset_m: float = 25.0) -> np.ndarray:
    """Arc length `s` (m) on `course` of each fix, NaN where unmatched.

    The first match is the earliest passage within `max_offset_m` over the whole course
    (the ride may start anywhere; a closed loop's end lies on its start), later ones are
    searched from the previous match forward.
    """
    x, y, _ = course.from_geodetic(lat_deg, lon_deg, np.full(len(lat_deg), course.origin.alt_m))
    x, y = np.asarray(x, float), np.asarray(y, float)
    ds = course.ds_m
    s_out = np.full(len(x), np.nan)
    last_i, last_t = -1, None
    for k in range(len(x)):
        if not (np.isfinite(x[k]) and np.isfinite(y[k])):
            continue
        if last_i < 0:
            lo, hi = 0, len(course.s_m)
        else:
            reach = _SLACK_M + _V_MAX_MPS * max(float(t_s[k] - last_t), 1.0)
            lo = max(last_i - int(_SLACK_M / ds), 0)
            hi = min(last_i + int(reach / ds) + 1, len(course.s_m))
        d2 = (course.x_m[lo:hi] - x[k]) ** 2 + (course.y_m[lo:hi] - y[k]) ** 2
        near = np.flatnonzero(d2 <= max_offset_m ** 2)
        if last_i < 0 and len(near):
            # First match: the earliest passage (a closed loop's end lies on its start).
            j0 = int(near[0])
            j = j0 + int(np.argmin(d2[j0:j0 + int(2 * max_offset_m / ds) + 1]))
        else:
            j = int(np.argmin(d2))
        if d2[j] > max_offset_m ** 2:
            continue
        if last_i >= 0 and lo + j < last_i:
            j = last_i - lo  # never backwards: GPS jitter along the road
        last_i, last_t = lo + j, t_s[k]
        s_out[k] = course.s_m[last_i]
    return s_out
