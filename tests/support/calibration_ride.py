"""The virtual rider's calibration ride: a known truth to recover.

Shared by tests/calibration/test_calibration.py and bench/bench_calibration.py: a ~35 km
synthetic course of flats, 5 % climbs and descents and 20 m corners, a CP-test protocol
of maximal efforts the virtual rider follows by distance, and its sensor samples as a
1 Hz recording.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from itt_planner.course.builder import build_course
from itt_planner.course.geometry import Course
from itt_planner.course.track_files import Recording
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed
from itt_planner.model.rider import Rider
from itt_planner.model.steady import steady_speed_mps
from itt_planner.ocp.plan import PLAN_ARRAYS, Plan
from itt_planner.sim import SimResult

TRUTH = Rider(name="truth", mass_kg=75.0, drag_area_m2=0.30, crr=0.005, critical_power_w=300.0,
              w_prime_j=20000.0)
#: Maximal efforts of the synthetic ride (s): a CP test protocol, with recoveries between.
EFFORTS_S = (120, 240, 480, 900)
#: Altitude of the course's origin (m).
ALT_M = 200.0


def calibration_course() -> Course:
    """~35 km of flats, 5 % climbs and descents, and 20 m corners (synthetic)."""
    segs: list[dict[str, object]] = []
    for _ in range(9):
        segs += [{"type": "straight", "length_m": 1500, "grade_pct": 0},
                 {"type": "straight", "length_m": 1200, "grade_pct": 5},
                 {"type": "clothoid", "length_m": 10, "radius_m": 20, "direction": "left"},
                 {"type": "arc", "angle_deg": 90, "radius_m": 20, "direction": "left"},
                 {"type": "clothoid", "length_m": 10},
                 {"type": "straight", "length_m": 1200, "grade_pct": -5}]
    spec = {"name": "calibration-synthetic", "segments": segs,
            "origin": {"lat_deg": 45.0, "lon_deg": 10.0, "alt_m": ALT_M}}
    return build_course(spec, source="tests/support/calibration_ride.py")


def effort_plan(course: Course, rider: Rider) -> Plan:
    """A 'plan' the virtual rider follows by distance: 0.6 CP, and each effort of
    `EFFORTS_S` at CP + W'/T over the distance a steady rider covers in T (W' spent)."""
    s = course.s_m
    grade = np.tan(course.beta_rad)
    power = np.full(len(s), 0.6 * rider.critical_power_w)
    start = 1500
    for duration in EFFORTS_S:
        p = rider.critical_power_w + rider.w_prime_j / duration
        t, k = 0.0, start
        while t < duration:
            t += course.ds_m / steady_speed_mps(p, rider, grade=float(grade[k]))
            k += 1
        power[start:k] = p
        start = k + 4000  # ~8 min at 0.6 CP: W' mostly back (Skiba tau ~ 450 s)
    n = len(s)
    arrays: dict[str, Any] = {name: np.zeros(n) for name in PLAN_ARRAYS}
    # A high advised speed: the rider brakes only for grip, as a rider without a plan.
    arrays.update(s_m=s, power_w=power, v_mps=np.full(n, 25.0), t_s=s / 8.0)
    return Plan(model="1d", solver_status="synthetic", iterations=0, solve_time_s=0.0, **arrays)


def sensor_recording(result: SimResult, rng: np.random.Generator) -> Recording:
    """The sensor samples as a 1 Hz recording; the altimeter adds 0.3 m of noise."""
    gps = {round(x.stamp_s, 3): x for x in result.samples if isinstance(x, GpsFix)}
    speed = {round(x.stamp_s, 3): x.speed_mps for x in result.samples if isinstance(x, WheelSpeed)}
    power = {round(x.stamp_s, 3): x.power_w for x in result.samples if isinstance(x, PowerReading)}
    t = sorted(gps)
    return Recording(
        path=Path("synthetic-ride.csv"), sha256="",
        lat_deg=np.array([gps[k].lat_deg for k in t]),
        lon_deg=np.array([gps[k].lon_deg for k in t]),
        ele_m=np.array([gps[k].alt_m for k in t]) + rng.normal(0.0, 0.3, len(t)),
        time_s=np.array(t) + 1.7e9, speed_mps=np.array([speed.get(k, np.nan) for k in t]),
        power_w=np.array([power.get(k, np.nan) for k in t]))
