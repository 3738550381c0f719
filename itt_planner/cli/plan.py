"""`itt-planner plan` and `itt-planner compare-riders`: full-course OCP solves.

Exit codes of `plan`: 0 the plan converged and passed its verification (an independent
replay, `verify`); 1 unusable input (bad course, rider or settings: one `{"error", "type"}`
JSON object with `--json`); 3 the plan is not fit for use - the solver stopped without
converging (iteration/time cap, infeasible problem, e.g. a rider too weak for a wall) or
the plan failed its verification (`status` "invalid"): the plan's figures are still
printed, with `status`, `solver_status` and `"success": false`. With
`--allow-unconverged` such a plan exits 0, says `"allowed_unconverged": true` in the JSON
and warns on stderr.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import typer

from itt_planner.cli._app import (
    AIR_DENSITY_OPTION,
    AIR_TEMPERATURE_OPTION,
    JSON_OPTION,
    MU_OPTION,
    WIND_FROM_DEG_OPTION,
    WIND_KMH_OPTION,
    app,
    day_conditions,
    emit,
    errors_to_exit,
)
from itt_planner.units import MPS_TO_KMH

#: Exit code of `plan` when the solver stopped without converging (module docstring).
EXIT_NOT_CONVERGED = 3


def plan_summary(plan: Any, course: Any) -> dict[str, Any]:
    """The figures `plan --json` prints (edge units only in the *_kmh / *_deg fields)."""
    import numpy as np  # noqa: PLC0415

    from itt_planner.ocp.plan import corner_table, splits  # noqa: PLC0415

    dt = np.diff(plan.t_s)
    mean_power = float(np.sum(plan.power_w[:-1] * dt) / max(float(np.sum(dt)), 1e-9))
    # The 1D plan's corner speeds read like the 3D's: say that nothing limits them.
    warnings = [] if plan.model != "1d" or not course.corners else [
        (f"the 1D model has no corners: through the course's {len(course.corners)} "
         f"corner(s) (down to R {min(c.min_radius_m for c in course.corners):.0f} m) no "
         "grip or lean limits its speed; --model 3d plans them")]
    return {
        "course": course.name, "model": plan.model,
        "finish_time_s": round(plan.finish_time_s, 2),
        "mean_speed_kmh": round(MPS_TO_KMH * course.length_m / plan.finish_time_s, 2),
        "mean_power_w": round(mean_power, 1),
        "w_prime_end_j": round(float(plan.w_prime_j[-1]), 1),
        "w_prime_min_j": round(float(plan.w_prime_j.min()), 1),
        "max_lean_deg": round(math.degrees(float(np.max(np.abs(plan.phi_rad)))), 2),
        "max_friction_use": round(float(plan.friction_use.max()), 4),
        "solve_time_s": round(plan.solve_time_s, 3), "iterations": plan.iterations,
        "n_nodes": plan.n_nodes, "status": plan.status, "solver_status": plan.solver_status,
        "success": bool(plan.meta.get("success", False)),
        "verified": (None if plan.meta.get("verification") is None
                     else bool(plan.meta["verification"]["verified"])),
        "verification": plan.meta.get("verification"),
        "attempts": plan.meta.get("attempts", []),
        "warnings": warnings,
        "conditions": dict(plan.meta.get("conditions", {})),
        "corners": [
            {"apex_s_m": round(r.apex_s_m, 1), "min_radius_m": round(r.min_radius_m, 1),
             "braking_s_m": None if r.braking_s_m is None else round(r.braking_s_m, 1),
             "entry_speed_kmh": round(MPS_TO_KMH * r.entry_speed_mps, 1),
             "apex_speed_kmh": round(MPS_TO_KMH * r.apex_speed_mps, 1),
             "exit_speed_kmh": round(MPS_TO_KMH * r.exit_speed_mps, 1),
             "max_lean_deg": round(math.degrees(r.max_lean_rad), 1), "time_s": round(r.time_s, 2)}
            for r in corner_table(plan, course.corners)],
        "splits": [{k: round(v, 2) for k, v in row.items()} for row in splits(plan)],
    }


def _human(r: dict[str, Any]) -> str:
    lines = [(f"{r['course']} ({r['model']}): {r['finish_time_s']:.1f} s, "
              f"{r['mean_speed_kmh']} km/h, "
              f"{r['mean_power_w']} W, W' end {r['w_prime_end_j']:.0f} J, max lean "
              f"{r['max_lean_deg']} deg  [{r['status']}: {r['solver_status']}, "
              f"verified {r['verified']}, {r['iterations']} it, "
              f"{r['n_nodes']} nodes, {r['solve_time_s']} s]")]
    lines += [f"  corner {c['apex_s_m'] / 1000:6.2f} km R {c['min_radius_m']:5.1f} m: "
              f"{c['entry_speed_kmh']}/{c['apex_speed_kmh']}/{c['exit_speed_kmh']} km/h, "
              f"lean {c['max_lean_deg']} deg, {c['time_s']} s" for c in r["corners"]]
    lines += [f"  {s['s_m'] / 1000:6.2f} km  {s['elapsed_s']:8.1f} s  (+{s['split_s']:.1f} s)"
              for s in r["splits"]]
    return "\n".join(lines + [f"warning: {w}" for w in r["warnings"]])


@app.command("plan")
def plan_cli(
    course: str = typer.Option(..., "--course", help="GPS track, saved course, or demo name."),
    rider: str = typer.Option("paper", "--rider", help="Rider preset or YAML file."),
    model: str = typer.Option("3d", "--model", help="3d or 1d."),
    output: Path | None = typer.Option(None, "--output", "-o", help="Write the .plan.npz here."),
    mu: float = MU_OPTION,
    wind_kmh: float = WIND_KMH_OPTION,
    wind_from_deg: float = WIND_FROM_DEG_OPTION,
    air_density_kgpm3: float | None = AIR_DENSITY_OPTION,
    air_temperature_c: float | None = AIR_TEMPERATURE_OPTION,
    max_time_s: float | None = typer.Option(
        None, "--max-time-s", help="Solver time budget (s); default scales with the course."),
    max_iter: int | None = typer.Option(
        None, "--max-iter", help="Solver iteration budget; default scales with the course."),
    line: str = typer.Option(
        "centre", "--line",
        help="1D only: ride the centre line, or 'shortest': the shortest line within the "
             "road (the 3D plan takes its own line; on the centre line the 1D rides farther)."),
    allow_unconverged: bool = typer.Option(
        False, "--allow-unconverged",
        help="Exit 0 even if the plan did not converge or failed verification (says so)."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Solve the minimum-time pacing and cornering OCP over a whole course, and verify it.

    Exit code 0: converged and verified; 1: unusable input; 3: the solver stopped at a
    cap, found the problem infeasible, or the plan failed verification (the figures are
    printed with that status), unless --allow-unconverged.
    """
    from itt_planner.course.loader import load_course  # noqa: PLC0415
    from itt_planner.errors import SolveError  # noqa: PLC0415
    from itt_planner.model.conditions import own_air_note  # noqa: PLC0415
    from itt_planner.model.rider import load_rider  # noqa: PLC0415
    from itt_planner.ocp.cache import solve_keeping_point  # noqa: PLC0415
    from itt_planner.ocp.course_settings import OcpSettings  # noqa: PLC0415
    from itt_planner.ocp.line_plan import solve_plan_on_line  # noqa: PLC0415

    with errors_to_exit(as_json):
        if line not in ("centre", "shortest") or (line == "shortest" and model != "1d"):
            raise SolveError(f"--line {line!r}: 'centre', or 'shortest' with --model 1d "
                             "(the 3D model chooses its own line)", status="invalid_input")
        built = load_course(course)
        conditions = day_conditions(mu, wind_kmh, wind_from_deg, air_density_kgpm3,
                                    air_temperature_c, built.mean_altitude_m)
        settings = OcpSettings(max_cpu_time_s=max_time_s, max_iter=max_iter)
        # With its solver point: a node given this plan (`--plan`) re-solves warm. On the
        # shortest line the point is the line's NLP's, so none is kept.
        solved = (solve_plan_on_line(built, load_rider(rider), conditions, settings)
                  if line == "shortest" else
                  solve_keeping_point(built, load_rider(rider), conditions, settings, model))
        result = plan_summary(solved, built) | {"line": line}
        if air_temperature_c is not None:
            result["conditions"]["air_temperature_c"] = air_temperature_c
        day_air_given = air_density_kgpm3 is not None or air_temperature_c is not None
        if not day_air_given and (note := own_air_note(
                built.mean_altitude_m, conditions.air_density_kgpm3,
                built.recorded_air_temperature_c)):
            result["warnings"].append(note)
        if not result["success"] and allow_unconverged:
            result["allowed_unconverged"] = True
        if output is not None:
            # Where the course came from, so `report PLAN` finds a file course by itself.
            solved.meta["course_spec"] = (str(Path(course).resolve()) if Path(course).exists()
                                          else course)
            result["output"] = str(solved.save(output))
        emit(result, as_json, _human)
    if not result["success"]:
        typer.echo(f"WARNING: the plan is {solved.status} ({solved.solver_status}"
                   + (f", worst mismatch {solved.meta['verification']['worst']} at s = "
                      f"{solved.meta['verification']['worst_s_m']:.0f} m"
                      if solved.status == "invalid" else "")
                   + "): not fit for use" + ("; used anyway (--allow-unconverged)"
                                             if allow_unconverged else ""), err=True)
        if not allow_unconverged:
            raise typer.Exit(code=EXIT_NOT_CONVERGED)


@app.command("compare-riders")
def compare_riders_cli(
    course: str = typer.Option(..., "--course", help="GPS track, saved course, or demo name."),
    as_json: bool = JSON_OPTION,
) -> None:
    """The three virtual riders x both models: finish, longest descent, sharpest corner."""
    from itt_planner.course.loader import load_course  # noqa: PLC0415
    from itt_planner.ocp.analysis import compare_riders  # noqa: PLC0415

    with errors_to_exit(as_json):
        rows = compare_riders(load_course(course))
        emit({"course": course, "riders": rows}, as_json, lambda r: "\n".join(
            f"{x['rider']:10s} {x['model']}: {x['finish_time_s']:8.1f} s, descent "
            f"{x['descent_time_s']:7.1f} s, sharpest corner {x['corner_time_s']:5.2f} s "
            f"[{x['solver_status']}]" for x in r["riders"]))
