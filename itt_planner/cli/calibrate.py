"""`itt-planner calibrate` and `itt-planner validate`: a rider from ride files, and the
models and plans checked against rides (itt_planner.calibration)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from itt_planner.cli._app import JSON_OPTION, app, emit, errors_to_exit


def _human_calibration(r: dict[str, Any]) -> str:
    lines = [f"rider from {', '.join(r['rides'])}:"]
    lines += [f"  {src}: {n} s filled at 1 s between sparse records (smart recording)"
              for src, n in zip(r["rides"], r["filled_s"], strict=True) if n]
    lines += [f"  {src}: its power only, for CP and W' ({why})"
              for src, why in r["power_only"].items()]
    a = r["aero"]
    if a:
        mass = (f"mass {a['mass_kg']} +- {a['mass_std_kg']} kg (estimated)"
                if a["mass_estimated"] else f"mass {a['mass_kg']} kg")
        crr = f"crr {a['crr']} (fixed: {a['crr_note']})" if a["crr_fixed"] else \
            f"crr {a['crr']} +- {a['crr_std']}"
        lines.append(f"  CdA {a['cda_m2']} +- {a['cda_std_m2']} m^2, {crr}, {mass}, "
                     f"{a['n_stretches']} stretches, VE RMSE {a['virtual_elevation_rmse_m']} m")
    for key in ("cp_2p", "cp_3p"):
        c = r[key]
        if c:
            lines.append(f"  {key}: CP {c['cp_w']} +- {c['cp_std_w']} W, W' {c['w_prime_j']} +- "
                         f"{c['w_prime_std_j']} J on {c['durations_s'][0]}-{c['durations_s'][-1]}"
                         f" s, R2 {c['r2']}, RMSE {c['rmse_w']} W")
    c = r["cornering"]
    if c:
        lines.append(f"  cornering: {c['max_lateral_accel_mps2']} +- {c['std_mps2']} m/s^2 "
                     f"(lean {c['max_lean_deg']} deg, {c['corners_used']} corners)")
    if len(r["setups"]) > 1:
        lines += [f"  setup {name}: CdA {row.get('cda_m2')} +- {row.get('cda_std_m2')} m^2 "
                  f"({len(row['rides'])} rides)" for name, row in r["setups"].items()]
    lines += [f"  REFUSED {k}: {v}" for k, v in r["refusals"].items()]
    lines += [f"  WARNING {k}: {v}" for k, v in r["warnings"].items()]
    if r.get("output"):
        lines.append(f"  wrote {', '.join([r['output'], *r.get('output_per_setup', [])])}")
    return "\n".join(lines)


@app.command("calibrate")
def calibrate_cli(
    rides: list[Path] = typer.Argument(
        ..., help="Ride files (.fit/.tcx/.gpx/.csv/.pwx, or gzipped) of one rider."),
    output: Path | None = typer.Option(None, "--output", "-o", help="Write the rider YAML here."),
    course: str | None = typer.Option(None, "--course",
                                      help="Course of every ride (default: each ride's track)."),
    mass_kg: float | None = typer.Option(None, "--mass-kg",
                                         help="Rider + bike mass (default: estimated)."),
    efficiency: float = typer.Option(1.0, "--drivetrain-efficiency",
                                     help="Wheel power / measured power."),
    temperature_c: float | None = typer.Option(None, "--temperature-c",
                                               help="Air temperature (default: the record's)."),
    allow_virtual: bool = typer.Option(False, "--allow-virtual",
                                       help="Fit a ride whose speed is simulated anyway."),
    setup: list[str] = typer.Option([], "--setup", help="Setup (position or bike) of each ride, "
                                    "in order (repeat): one CdA per setup. Default: the FIT "
                                    "files' bike profile names, else one setup."),
    report: Path | None = typer.Option(None, "--report", help="Write an HTML report here."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Fit CdA, crr, CP, W' and the cornering limit of one rider to ride files."""
    from itt_planner.calibration import CalibrationOptions, calibrate, write_rider  # noqa: PLC0415
    from itt_planner.calibration.calibrate import write_setup_riders  # noqa: PLC0415

    with errors_to_exit(as_json):
        options = CalibrationOptions(mass_kg=mass_kg, drivetrain_efficiency=efficiency,
                                     temperature_c=temperature_c, course=course,
                                     allow_virtual=allow_virtual, setups=tuple(setup),
                                     name=output.name.split(".")[0] if output else "calibrated")
        result = calibrate(list(rides), options)
        summary = result.as_dict()
        if output is not None:
            summary["output"] = str(write_rider(result, output))
            per_setup = write_setup_riders(result, output)
            if per_setup:
                summary["output_per_setup"] = [str(p) for p in per_setup]
        if report is not None:
            from itt_planner.calibration.figures import write_calibration_report  # noqa: PLC0415

            summary["report"] = str(write_calibration_report(result, report))
        emit(summary, as_json, _human_calibration)


def _human_validation(r: dict[str, Any]) -> str:
    if "holdout" in r:
        return "\n".join(
            f"held out {h['held_out']}: " + (f"REFUSED {h['refused']}" if "refused" in h else
                                             f"finish {h['finish_error_pct']:+.2f} %, speed MAE "
                                             f"{h['mae_kmh']} km/h (floor {h['noise_floor_kmh']})")
            for h in r["holdout"])
    values = ", ".join(f"{k} {v}" for k, v in r["rider_values"].items())
    head = (f"{r['ride']} on {r['course']} ({r['covered_m'] / 1000:.1f} km; the ride's speed x "
            f"moving time / course length {r['speed_distance_ratio']}), rider {r['rider']} "
            f"({values}):")
    lines = [head, *validation_lines(r)]
    if "elevation" in r:  # the profile the replays climbed, and why
        lines.insert(1, f"  elevation the replays climb: {r['elevation']}")
    return "\n".join(lines)


def validation_lines(r: dict[str, Any]) -> list[str]:
    """A validation's physics and plan checks (`Validation.figures`), a line each, as
    `validate` and `report` print them."""
    from itt_planner.calibration.physics_check import unmodelled_lines  # noqa: PLC0415

    lines = []
    for p in r["physics"]:
        inputs = {k: v for k, v in p.get("ride_inputs", {}).items() if k != "sheltered"}
        lines.append(f"  physics {p['model']} ({p['conditions']}): finish {p['finish_s']} s vs "
                     f"{p['ride_moving_s']} s ({p['finish_error_pct']:+.2f} %), speed MAE "
                     f"{p['mae_kmh']} RMSE {p['rmse_kmh']} bias {p['bias_kmh']} km/h, "
                     f"{100 * p['share_within_2kmh']:.0f} % within 2 km/h; noise floor "
                     f"{p['noise_floor_kmh']} km/h"
                     + (f"; ride's inputs {inputs}" if inputs else ""))
        lines += [f"    {line}" for line in unmodelled_lines(p)]
    if "physics_3d" in r:
        lines.append(f"  physics 3d: {r['physics_3d']}")
    lines += [f"  plan {p['model']} [{p['solver_status']}]: {p['plan_finish_s']} s vs ride "
              f"{p['ride_moving_s']} s ({p['plan_minus_ride_pct']:+.2f} %), power MAE "
              f"{p['power_mae_w']} W; plan - ride by kind (s): {p['time_by_kind_s']}"
              for p in r.get("plans", [])]
    return lines


@app.command("validate")
def validate_cli(
    rides: list[Path] = typer.Argument(..., help="Ride file(s); several with --holdout."),
    course: str | None = typer.Option(None, "--course",
                                      help="The ride's course (default: the ride's own track)."),
    rider: str | None = typer.Option(None, "--rider", help="Rider preset or YAML (not with "
                                     "--holdout, which calibrates its own)."),
    model: list[str] = typer.Option(["1d", "3d"], "--model",
                                    help="Models to replay the ride's power through (repeat)."),
    plan_model: list[str] = typer.Option([], "--plan-model",
                                         help="Also check the optimal plan (3d, 1d; repeat)."),
    holdout_flag: bool = typer.Option(False, "--holdout",
                                      help="Calibrate on all rides but one, validate on it."),
    mass_kg: float | None = typer.Option(None, "--mass-kg", help="Mass for --holdout fits."),
    temperature_c: float | None = typer.Option(None, "--temperature-c"),
    elevation: str = typer.Option(
        "auto", "--elevation", help="Profile the replays climb: auto (the ride's own altitude "
        "when the course was fitted from this ride), course, ride."),
    report: Path | None = typer.Option(None, "--report", help="Write an HTML report here."),
    cache_dir: Path = typer.Option(Path(".itt_cache"), "--cache-dir", help="Plan cache."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Replay a ride's power through the models and compare the plan with the ride."""
    from itt_planner.calibration import CalibrationError, CalibrationOptions  # noqa: PLC0415
    from itt_planner.calibration.validate import holdout, validate_ride  # noqa: PLC0415
    from itt_planner.course.loader import load_course  # noqa: PLC0415
    from itt_planner.model.rider import load_rider  # noqa: PLC0415

    with errors_to_exit(as_json):
        courses = [load_course(course or str(r)) for r in rides]
        if holdout_flag:
            emit(holdout(list(rides), courses, CalibrationOptions(
                mass_kg=mass_kg, temperature_c=temperature_c), tuple(model)),
                as_json, _human_validation)
            return
        if len(rides) != 1 or rider is None:
            raise CalibrationError("validate takes one ride and --rider (or --holdout with "
                                   "several rides)")
        val = validate_ride(rides[0], courses[0], load_rider(rider), models=tuple(model),
                            plan_models=tuple(plan_model), temperature_c=temperature_c,
                            elevation=elevation, cache_dir=cache_dir)
        if report is not None:
            from itt_planner.calibration.figures import write_validation_report  # noqa: PLC0415

            val.figures["report"] = str(write_validation_report(val, report))
        emit(val.figures, as_json, _human_validation)
