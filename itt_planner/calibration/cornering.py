"""The cornering limit a rider actually used: lateral acceleration in corners of known radius.

In each corner of the ride's course (`Course.corners`, radius from the fitted centre
line), the rider's slowest speed between entry and exit is the apex speed; the lateral
acceleration held there is `a_y = v^2 / R` and the steady lean `atan(a_y / g)` (E5 at
equilibrium). The rider's limit is the largest `a_y` over corners tighter than
`max_radius_m` (wide bends are taken at whatever speed the power gives and say
nothing about grip or nerve). A corner where `v^2 / R` exceeds what dry tyres give (1 g)
is a course-fit radius that is too small or a mismatched fix, not a rider: it is
dropped and counted. Its uncertainty propagates the speed noise and the
course fit's radius error (~25 % median on 3 m GPS noise, bench/RESULTS.md):
sigma_a / a = sqrt((2 sigma_v / v)^2 + (sigma_R / R)^2). Refused when the ride passes no
corner tight enough.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from itt_planner.calibration.matching import course_progress
from itt_planner.calibration.ride_data import CalibrationError, RideSeries
from itt_planner.course.geometry import Course
from itt_planner.model.conditions import GRAVITY_MPS2

#: Relative radius error of a course fitted from 1 Hz GPS (see module doc).
RADIUS_REL_ERROR = 0.25
#: Speed noise of a 1 Hz speed record (m/s).
SPEED_ERROR_MPS = 0.3


@dataclass(frozen=True)
class CornerSpeed:
    """One corner as ridden: course position, radius, apex speed, lateral acceleration."""

    apex_s_m: float
    radius_m: float
    speed_mps: float
    lateral_accel_mps2: float
    lean_deg: float


@dataclass(frozen=True)
class CorneringFit:
    """The largest lateral acceleration used, with its propagated uncertainty."""

    max_lateral_accel_mps2: float
    std_mps2: float
    max_lean_deg: float
    corners: tuple[CornerSpeed, ...]
    dropped: int = 0

    def as_dict(self) -> dict[str, object]:
        return {"max_lateral_accel_mps2": round(self.max_lateral_accel_mps2, 2),
                "std_mps2": round(self.std_mps2, 2), "max_lean_deg": round(self.max_lean_deg, 1),
                "corners_used": len(self.corners),
                "corners_dropped_over_1g": self.dropped}


def corner_speeds(ride: RideSeries, course: Course, max_radius_m: float = 50.0
                  ) -> list[CornerSpeed]:
    """Apex speed and lateral acceleration in every corner of `course` the ride passed."""
    s = course_progress(course, ride.lat_deg, ride.lon_deg, ride.t_s)
    out: list[CornerSpeed] = []
    for c in course.corners:
        if c.min_radius_m > max_radius_m:
            continue
        inside = np.flatnonzero((s >= c.entry_s_m) & (s <= c.exit_s_m))
        # A stop in the corner (junction, traffic) says nothing about the limit.
        if len(inside) == 0 or np.min(ride.v_mps[inside]) < 2.0:
            continue
        v = float(np.min(ride.v_mps[inside]))
        a = v * v / c.min_radius_m
        out.append(CornerSpeed(c.apex_s_m, c.min_radius_m, v, a,
                               math.degrees(math.atan(a / GRAVITY_MPS2))))
    return out


def fit_cornering(rides: list[RideSeries], courses: list[Course], max_radius_m: float = 50.0
                  ) -> CorneringFit:
    """The cornering limit over all rides (each with its own course).

    Raises:
        CalibrationError: no ride passed a corner tighter than `max_radius_m` at speed.
    """
    every = [c for ride, course in zip(rides, courses, strict=True)
             for c in corner_speeds(ride, course, max_radius_m)]
    corners = [c for c in every if c.lateral_accel_mps2 <= GRAVITY_MPS2]
    if not corners:
        names = ", ".join(r.source for r in rides)
        raise CalibrationError(f"{names}: no corner tighter than {max_radius_m:.0f} m ridden "
                               f"at speed within 1 g ({len(every)} over it: course radii too "
                               "small?); no cornering limit can be read")
    top = max(corners, key=lambda c: c.lateral_accel_mps2)
    rel = math.hypot(2 * SPEED_ERROR_MPS / top.speed_mps, RADIUS_REL_ERROR)
    return CorneringFit(top.lateral_accel_mps2, rel * top.lateral_accel_mps2, top.lean_deg,
                        tuple(corners), len(every) - len(corners))
