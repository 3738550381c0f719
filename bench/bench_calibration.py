"""Calibration and validation on the real rides: the figures of bench/RESULTS.md.

For every real ride found (tests/data/ or ../shared/data/): `calibrate` on the ride
(mass estimated unless it is not identified, then 80 kg), then `validate` with that
rider on the ride's own course (1D forward run with the ride's power; the 1D plan with
`--plan`). Prints one line per ride and a JSON object. Run:
`.venv/bin/python -m bench.bench_calibration [--plan]`.
"""

from __future__ import annotations

import json
import sys
import time

from itt_planner.calibration import CalibrationError, CalibrationOptions, calibrate
from itt_planner.calibration.validate import validate_ride
from itt_planner.course_loader import load_course
from tests.real_data import RIDES, locate


def main() -> None:
    with_plan = "--plan" in sys.argv
    rows = []
    for rel in RIDES:
        path = locate(rel)
        if path is None:
            print(f"{rel}: not found, skipped")
            continue
        t0 = time.perf_counter()
        course = load_course(path)
        row: dict[str, object] = {"ride": path.name, "course_km": round(course.length_m / 1000, 2)}
        try:
            fit = calibrate([path], CalibrationOptions(), courses=[course])
            if "aero" in fit.refusals and "mass is not identified" in fit.refusals["aero"]:
                row["mass_note"] = "mass not identified: 80 kg given"
                fit = calibrate([path], CalibrationOptions(mass_kg=80.0), courses=[course])
        except CalibrationError as err:
            row["refused"] = str(err)
            rows.append(row)
            print(f"{path.name}: REFUSED {err}")
            continue
        row["calibration"] = {k: v for k, v in fit.as_dict().items() if k != "mmp_w"}
        try:
            val = validate_ride(path, course, fit.rider, plan_models=("1d",) if with_plan else ())
            phys = {k: v for k, v in val.figures["physics"][0].items()
                    if k not in ("per_km", "per_corner")}
            row["physics_1d"] = phys
            if with_plan:
                row["plan_1d"] = {k: v for k, v in val.figures["plans"][0].items()
                                  if k != "sections"}
        except CalibrationError as err:
            row["validate_refused"] = str(err)
        row["wall_s"] = round(time.perf_counter() - t0, 1)
        rows.append(row)
        a = fit.aero
        p = row.get("physics_1d", {})
        print(f"{path.name}: CdA " + (f"{a.cda_m2:.3f} +- {a.cda_std_m2:.3f}, crr {a.crr:.4f}"
                                      f"{' (fixed)' if a.crr_fixed else ''}, mass {a.mass_kg:.0f}"
                                      if a else f"refused ({fit.refusals.get('aero', '')[:80]})")
              + (f"; CP {fit.cp_2p.cp_w:.0f} W, W' {fit.cp_2p.w_prime_j:.0f} J" if fit.cp_2p
                 else "")
              + (f"; 1D finish {p['finish_error_pct']:+.2f} %, MAE {p['mae_kmh']} km/h, floor "
                 f"{p['noise_floor_kmh']} km/h" if p else f"; {row.get('validate_refused', '')}"))
    print(json.dumps(rows, default=str))


if __name__ == "__main__":
    main()
