"""Calibration and validation on the real rides: the figures of bench/RESULTS.md.

For every real ride found (tests/data/ or ../shared/data/): `calibrate` on the ride
(mass estimated unless it is not identified, then 80 kg), then `validate` with that
rider on the ride's own course (1D replay of the ride's power in still air and in the
day's fitted wind, then with the ride's braking and stops too; 3D replay in the day's wind
with the ride's braking and stops; the 1D plan with `--plan`). First the synthetic truth of
tests/calibration against its fit. Prints lines per ride and a JSON object. Run:
`.venv/bin/python -m bench.bench_calibration [--plan] [NAME...]` (NAME: rides whose
path contains it).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from support.calibration_ride import ALT_M, TRUTH, calibration_course, effort_plan, sensor_recording
from support.real_data import RIDES, locate

from itt_planner.calibration import CalibrationError, CalibrationOptions, calibrate
from itt_planner.calibration.calibrate import CalibrationResult
from itt_planner.calibration.physics_check import unmodelled_lines
from itt_planner.calibration.validate import validate_ride
from itt_planner.course.geometry import Course
from itt_planner.course.loader import load_course
from itt_planner.model.conditions import Conditions, air_density_kgpm3
from itt_planner.model.rider import Rider
from itt_planner.sim import simulate_ride


def synthetic() -> dict[str, tuple[float, float, float]]:
    """The virtual rider's ride of tests/calibration (tests/support/calibration_ride.py):
    truth against the fit."""
    course = calibration_course()
    rho = float(air_density_kgpm3(ALT_M + 30.0, 15.0))
    sim = simulate_ride(course, TRUTH, effort_plan(course, TRUTH), policy="open_loop", seed=3,
                        conditions=Conditions(air_density_kgpm3=rho))
    rec = sensor_recording(sim, np.random.default_rng(4))
    fit = calibrate([rec], CalibrationOptions(mass_kg=TRUTH.mass_kg), courses=[course])
    free = calibrate([rec], CalibrationOptions(), courses=[course])
    assert fit.aero is not None, fit.refusals
    assert fit.cp_2p is not None, fit.refusals
    assert free.aero is not None, free.refusals
    out = {"cda": (TRUTH.drag_area_m2, fit.aero.cda_m2, fit.aero.cda_std_m2),
           "crr": (TRUTH.crr, fit.aero.crr, fit.aero.crr_std),
           "cp_w": (TRUTH.critical_power_w, fit.cp_2p.cp_w, fit.cp_2p.cp_std_w),
           "w_prime_j": (TRUTH.w_prime_j, fit.cp_2p.w_prime_j, fit.cp_2p.w_prime_std_j),
           "mass_free_kg": (TRUTH.mass_kg, free.aero.mass_kg, free.aero.mass_std_kg),
           "cda_mass_free": (TRUTH.drag_area_m2, free.aero.cda_m2, free.aero.cda_std_m2)}
    for name, (truth, got, sd) in out.items():
        print(f"synthetic {name}: truth {truth:g}, fitted {got:.5g} +- {sd:.2g} "
              f"({100 * (got / truth - 1):+.1f} %)")
    return out


def _calibrate(path: Path, course: Course, row: dict[str, Any]) -> CalibrationResult:
    """Calibrate on the ride: 80 kg where the mass is not identified; a virtual ride's
    refusal is printed and the game's rider fitted anyway (--allow-virtual)."""
    fit = calibrate([path], CalibrationOptions(), courses=[course])
    if "aero" in fit.refusals and "mass is not identified" in fit.refusals["aero"]:
        row["mass_note"] = "mass not identified: 80 kg given"
        fit = calibrate([path], CalibrationOptions(mass_kg=80.0), courses=[course])
    if "aero" in fit.refusals and "speed is simulated" in fit.refusals["aero"]:
        # Refused, as it should be; the game's rider is still worth one line.
        print(f"{path.name}: aero REFUSED ({fit.refusals['aero'][:120]}...); "
              "below: --allow-virtual, the game's rider")
        fit = calibrate([path], CalibrationOptions(allow_virtual=True), courses=[course])
    return fit


def _validate(path: Path, course: Course, rider: Rider, row: dict[str, Any],
              with_plan: bool) -> None:
    try:
        val = validate_ride(path, course, rider, plan_models=("1d",) if with_plan else ())
    except CalibrationError as err:
        row["validate_refused"] = str(err)
        return
    row["physics"] = [{k: v for k, v in ph.items() if k not in ("per_km", "per_corner")}
                      for ph in val.figures["physics"]]
    row["day_wind"] = val.figures["day_wind"]
    if "physics_3d" in val.figures:
        row["physics_3d"] = val.figures["physics_3d"]
    if with_plan:
        row["plan_1d"] = {k: v for k, v in val.figures["plans"][0].items() if k != "sections"}


def _print_row(path: Path, row: dict[str, Any], fit: CalibrationResult) -> None:
    a = fit.aero
    print(f"{path.name} ({row['wall_s']} s): CdA "
          + (f"{a.cda_m2:.3f} +- {a.cda_std_m2:.3f}, crr {a.crr:.4f}"
             f"{' (fixed)' if a.crr_fixed else ''}, mass {a.mass_kg:.0f} +- "
             f"{a.mass_std_kg:.1f} kg" if a else
             f"refused ({fit.refusals.get('aero', '')[:90]})")
          + (f"; CP {fit.cp_2p.cp_w:.0f} +- {fit.cp_2p.cp_std_w:.0f} W, W' "
             f"{fit.cp_2p.w_prime_j:.0f} J" if fit.cp_2p else "")
          + (f"; a_y {fit.cornering.max_lateral_accel_mps2:.2f} m/s^2" if fit.cornering
             else ""))
    for ph in row.get("physics", []):
        inputs = {k: v for k, v in ph.get("ride_inputs", {}).items() if k != "sheltered"}
        print(f"    {ph['model']} ({ph['conditions']}): finish {ph['finish_error_pct']:+.2f} %,"
              f" MAE {ph['mae_kmh']} RMSE {ph['rmse_kmh']} bias {ph['bias_kmh']} km/h, "
              f"{100 * ph['share_within_2kmh']:.0f} % within 2 km/h, floor "
              f"{ph['noise_floor_kmh']} km/h" + (f"; ride's inputs {inputs}" if inputs else ""))
        for line in unmodelled_lines(ph):
            print(f"        {line}")
    for key in ("physics_3d", "validate_refused"):
        if key in row:
            print(f"    {key}: {row[key]}")
    if "plan_1d" in row:
        pl = row["plan_1d"]
        print(f"    plan 1d [{pl['solver_status']}]: {pl['plan_minus_ride_pct']:+.2f} % vs ride, "
              f"power MAE {pl['power_mae_w']} W, plan - ride by kind {pl['time_by_kind_s']}")


def main() -> None:
    with_plan = "--plan" in sys.argv
    rows: list[dict[str, Any]] = [{"synthetic": synthetic()}]
    only = [a for a in sys.argv[1:] if not a.startswith("--")]
    for rel in RIDES:
        if only and not any(o in rel for o in only):
            continue
        path = locate(rel)
        if path is None:
            print(f"{rel}: not found, skipped")
            continue
        t0 = time.perf_counter()
        course = load_course(path)
        row: dict[str, Any] = {"ride": path.name, "course_km": round(course.length_m / 1000, 2)}
        rows.append(row)
        try:
            fit = _calibrate(path, course, row)
        except CalibrationError as err:
            row["refused"] = str(err)
            print(f"{path.name}: REFUSED {err}")
            continue
        row["calibration"] = {k: v for k, v in fit.as_dict().items() if k != "mmp_w"}
        _validate(path, course, fit.rider, row, with_plan)
        row["wall_s"] = round(time.perf_counter() - t0, 1)
        _print_row(path, row, fit)
    print(json.dumps(rows, default=str))


if __name__ == "__main__":
    main()
