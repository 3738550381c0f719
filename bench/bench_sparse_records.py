"""Benchmark: rides recorded sparsely (smart recording) or without a wheel-speed sensor.

Run: `.venv/bin/python -m bench.bench_sparse_records`. The vendored rides (`tests/data/`:
St John's, Ardennes; MIT) are thinned to a record every 1-7 s (random, three seeds: what
Garmin's smart recording keeps) and fed with and without their wheel speed. Printed, each
against the full 1 Hz ride in the same run:

- the live estimator's speed (`StateEstimator`, GPS and power, with or without the wheel
  speed) against the device's speed: MAE and bias, km/h;
- the W' balance at the rider calibrated on the 1 Hz ride (`WPrimeBalance`, the engine's
  `power_hold_s`): the lowest raw balance and the CP the power held proves;
- `calibrate` on the thinned ride: CdA, crr, mass, CP, W' and the seconds it filled;
- the course fitted to the thinned track: loop or not, length, corners.
No timings: these are accuracy figures (deterministic).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from itt_planner.calibration import CalibrationOptions, calibrate
from itt_planner.course.fit import fit_course
from itt_planner.course.geometry import Course
from itt_planner.course.track_files import Recording, read_recording
from itt_planner.live.estimate import StateEstimator
from itt_planner.live.estimator_settings import EstimatorSettings
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed
from itt_planner.live.wprime_balance import WPrimeBalance
from itt_planner.model.rider import Rider
from itt_planner.sim import smart_recording

ROOT = Path(__file__).resolve().parents[1]
RIDES = ("edge810_vector_stjohns_2013.fit", "edge1000_ardennes_2019.fit")
SEEDS = (1, 2, 3)
PROOF_DURATIONS_S = (300.0, 600.0, 1200.0, 2400.0)


def speed_error(rec: Recording, course: Course, rider: Rider, wheel: bool) -> str:
    assert rec.time_s is not None
    assert rec.speed_mps is not None
    assert rec.power_w is not None
    est = StateEstimator(course, WPrimeBalance(rider, EstimatorSettings().power_hold_s))
    error = []
    for i in range(len(rec)):
        stamp = float(rec.time_s[i])
        est.on_gps(GpsFix(stamp, float(rec.lat_deg[i]), float(rec.lon_deg[i]),
                          float(rec.ele_m[i])))
        if wheel:
            est.on_speed(WheelSpeed(stamp, float(rec.speed_mps[i])))
        est.on_power(PowerReading(stamp, float(rec.power_w[i])))
        state = est.state(stamp)
        if state is not None and rec.speed_mps[i] > 1.0:
            error.append(3.6 * (state.speed_mps - float(rec.speed_mps[i])))
    e = np.array(error)
    return f"{np.mean(np.abs(e)):.2f} / {np.mean(e):+.2f}"


def balance(rec: Recording, rider: Rider) -> str:
    assert rec.time_s is not None
    assert rec.power_w is not None
    bal = WPrimeBalance(rider, EstimatorSettings().power_hold_s)
    lowest = np.inf
    for stamp, power in zip(rec.time_s, np.nan_to_num(rec.power_w), strict=True):
        bal.add(float(stamp), float(power))
        lowest = min(lowest, bal.raw_j(float(stamp)))
    cp, over_s, _ = bal.proven_critical_power(PROOF_DURATIONS_S)
    return f"{lowest / 1000:+.1f} kJ, {cp:.0f} W over {over_s:.0f} s"


def calibration(rec: Recording) -> tuple[Rider, str]:
    result = calibrate([rec], CalibrationOptions())
    r = result.rider
    cells = (f"CdA {r.drag_area_m2:.4f} crr {r.crr:.4f} mass {r.mass_kg:.1f} "
             f"CP {r.critical_power_w:.1f} W' {r.w_prime_j:.0f} filled {result.rides[0].filled_s} s"
             + (f" refused {sorted(result.refusals)}" if result.refusals else ""))
    return r, cells


def main() -> None:
    print("ride | records | estimator speed MAE / bias km/h: wheel, GPS only | W' lowest, "
          "proven CP | calibrate | course")
    for name in RIDES:
        full = read_recording(ROOT / "tests" / "data" / name)
        rider, cal = calibration(full)
        course = fit_course(full)
        runs = [("1 Hz", full)] + [(f"thinned {s}", smart_recording(full, s)) for s in SEEDS]
        for label, rec in runs:
            own = course if rec is full else fit_course(rec)
            if rec is not full:
                cal = calibration(rec)[1]
            print(" | ".join([
                f"{name} {label}", str(len(rec)),
                (f"{speed_error(rec, course, rider, True)}, "
                 f"{speed_error(rec, course, rider, False)}"),
                balance(rec, rider), cal,
                (f"{'loop' if own.closed_loop else 'point to point'} "
                 f"{own.length_m / 1e3:.2f} km {len(own.corners)} corners")]), flush=True)


if __name__ == "__main__":
    main()
