"""The calibrated rider and the ride's validation as sections of `itt-planner report`.

The report of a plan (or of a replayed ride) gains two sections (`view.report_sections`):
- *calibrated rider*, when the rider is a file `calibrate` wrote (`rider_file`): each
  value with its uncertainty and source, the rides it was fitted on, the refusals, and
  whether the plan drawn was solved for these values;
- *validation*, when a ride with power is known (`--ride`, or the course's own source
  file: a course fitted to a ride): `validate.validate_ride` (the physics check, each
  model replaying the ride's power) and `plan_check` of the plan drawn against that ride.
"""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path
from typing import Any

from itt_planner.calibration.figures import validation_figures
from itt_planner.calibration.physics_check import unmodelled_lines
from itt_planner.calibration.plan_check import plan_check
from itt_planner.calibration.rider_file import CalibratedRiderFile
from itt_planner.calibration.validate import Validation, validate_ride
from itt_planner.course.geometry import Course
from itt_planner.course.track_files import track_format
from itt_planner.model.rider import Rider
from itt_planner.ocp.plan import Plan
from itt_planner.view.report_sections import ReportSection

#: Corners listed in the validation section: the worst by speed MAE.
WORST_CORNERS = 10


def course_ride(course: Course) -> Path | None:
    """The ride file a course was fitted to, when it still exists (a GPS-course YAML's
    source reads `course.yaml (ride.fit)`); None for a built or demo course."""
    for candidate in (course.source, *re.findall(r"\(([^()]*)\)$", course.source)):
        path = Path(candidate)
        if track_format(path) and path.is_file():
            return path
    return None


def validate_for_report(ride: Path, course: Course, rider: Rider, plan: Plan,
                        models: tuple[str, ...], cache_dir: Path) -> Validation:
    """`validate_ride` (physics check with `models`) and the plan check of `plan` itself.

    Raises:
        CalibrationError: the ride is unusable (no power, too short) or not on `course`.
    """
    val = validate_ride(ride, course, rider, models=models, cache_dir=cache_dir)
    val.plans.append(plan)
    val.figures["plans"] = [plan_check(plan, val.on_course, course)]
    return val


def _unexplained_text(p: dict[str, Any]) -> str:
    """The power the model does not explain, as a phrase ('' without the ride's inputs)."""
    inputs = p.get("ride_inputs") or {}
    if "unexplained_sd_w" not in inputs:
        return ""
    return (f"; power unexplained {inputs['unexplained_mean_w']:+} W, spread "
            f"{inputs['unexplained_sd_w']} W over {inputs['unexplained_windows']} "
            "braking-free 500 m windows")


def _physics_line(p: dict[str, Any]) -> str:
    return (f"finish {p['finish_s']} s vs {p['ride_moving_s']} s moving "
            f"({p['finish_error_pct']:+.2f} %); speed MAE {p['mae_kmh']}, RMSE {p['rmse_kmh']}, "
            f"bias {p['bias_kmh']:+} km/h (noise floor {p['noise_floor_kmh']}); "
            f"{100 * p['share_within_2kmh']:.0f} % of the distance within +-2 km/h"
            + _unexplained_text(p) + "".join(f"; {line}" for line in unmodelled_lines(p)))


def three_d_gain(physics: list[dict[str, Any]]) -> str | None:
    """What the 3D model buys over the 1D one in the same run (the ride's inputs, the same
    air): the change of speed MAE and finish error; None without both."""
    by_model = {(p["model"], p["conditions"]): p for p in physics}
    for (model, label), p3 in by_model.items():
        p1 = by_model.get(("1d", label))
        if model == "3d" and p1 is not None:
            return (f"({label}) speed MAE {p1['mae_kmh']} -> {p3['mae_kmh']} km/h, finish "
                    f"error {p1['finish_error_pct']:+.2f} -> {p3['finish_error_pct']:+.2f} %")
    return None


def validation_summary(val: Validation) -> dict[str, Any]:
    """The validation's figures for the report's JSON (per km and per corner included)."""
    out = dict(val.figures)
    gain = three_d_gain(out["physics"])
    if gain is not None:
        out["three_d_vs_one_d"] = gain
    return out


def validation_section(val: Validation) -> ReportSection:
    """The physics and plan checks: one row per model run, the plan drawn against the
    ride, per km and the worst corners of the last run (the ride's inputs, 3D if run)."""
    f = val.figures
    rows: dict[str, object] = {
        "ride": f["ride"], "rider": f"{f['rider']} ({f['rider_values']})",
        "covered_km": round(f["covered_m"] / 1000, 2), "matched_share": f["matched_share"],
        "ride_speed_x_time_over_course_length": f.get("speed_distance_ratio", "-"),
        "air_density_kgpm3": f["air_density_kgpm3"], "day_wind": f["day_wind"] or "-"}
    for p in f["physics"]:
        rows[f"physics {p['model']} ({p['conditions']})"] = _physics_line(p)
    if "physics_3d" in f:
        rows["physics 3d"] = f"not run: {f['physics_3d']}"
    gain = three_d_gain(f["physics"])
    if gain is not None:
        rows["3d vs 1d"] = gain
    for p in f.get("plans", []):
        rows[f"plan {p['model']} [{p['solver_status']}]"] = (
            f"{p['plan_finish_s']} s vs ride {p['ride_moving_s']} s "
            f"({p['plan_minus_ride_pct']:+.2f} %); power MAE {p['power_mae_w']} W (plan mean "
            f"{p['plan_mean_power_w']} W, ride {p['ride_mean_power_w']} W); plan - ride by "
            f"kind (s): {p['time_by_kind_s']}")
    last = f["physics"][-1] if f["physics"] else None
    tables = []
    if last is not None:
        tables.append((f"per km: {last['model']} ({last['conditions']})",
                       tuple(last["per_km"])))
        worst = sorted(last["per_corner"], key=lambda c: -c["mae_kmh"])[:WORST_CORNERS]
        tables.append(((f"the {len(worst)} corners of largest speed MAE of "
                       f"{len(last['per_corner'])}: {last['model']} ({last['conditions']})"),
                       tuple(sorted(worst, key=lambda c: c["apex_s_m"]))))
    return ReportSection(
        "Validation against the ride", rows, tuple(tables), tuple(validation_figures(val)),
        note="Each model replays the ride's own power along the course (speed against the "
             "ride's 5 s smoothed speed; the noise floor is the raw GPS speed's MAE against "
             "it); the power unexplained is what the ride got beyond the model at the ride's "
             "speed and power (wind gusts, drafting, position, elevation): its spread is "
             "what keeps the replay's speed off the ride's. The plan row is the plan drawn "
             "above against the ride's moving time.")


def calibration_summary(cal: CalibratedRiderFile, rider: Rider, plan: Plan | None
                        ) -> dict[str, Any]:
    """The calibrated rider's values with their notes, and whether `plan` was solved for
    them (`plan_rider_differs`: field -> [plan's, file's] values)."""
    fields = {f.name for f in dataclasses.fields(Rider)}
    values = {k: {"value": v, **({"note": cal.notes[k]} if k in cal.notes else {})}
              for k, v in cal.values.items() if k in fields and k != "name"}
    out: dict[str, Any] = {"file": str(cal.path), "rides": list(cal.sources), "values": values,
                           "conditions": list(cal.conditions), "refusals": dict(cal.refusals),
                           "warnings": dict(cal.warnings)}
    planned = plan.meta.get("rider") if plan is not None else None
    if isinstance(planned, dict):
        out["plan_rider_differs"] = {
            k: [planned.get(k), getattr(rider, k)] for k in values
            if not _same(planned.get(k), getattr(rider, k))}
    return out


def _same(a: object, b: object) -> bool:
    if isinstance(a, int | float) and isinstance(b, int | float):
        return math.isclose(float(a), float(b), rel_tol=1e-6)
    return a == b


def calibration_section(summary: dict[str, Any]) -> ReportSection:
    """`calibration_summary` as a report section."""
    rows: dict[str, object] = {"file": summary["file"], "fitted_on": summary["rides"]}
    for name, v in summary["values"].items():
        rows[name] = f"{v['value']}" + (f"  ({v['note']})" if "note" in v else "")
    rows.update({f"refused {k}": f"{v} (the preset's value kept)"
                 for k, v in summary["refusals"].items()})
    rows.update({f"warning {k}": v for k, v in summary.get("warnings", {}).items()})
    if summary["conditions"]:
        rows["conditions_of_the_rides"] = summary["conditions"]
    if "plan_rider_differs" in summary:
        differs = summary["plan_rider_differs"]
        rows["plan_solved_for_this_rider"] = (
            "yes" if not differs else
            "no: " + ", ".join(f"{k} plan {a} vs file {b}" for k, (a, b) in differs.items()))
    return ReportSection("Calibrated rider", rows,
                         note="Fitted by `itt-planner calibrate`; each value's uncertainty "
                              "and source as the rider file records it.")
