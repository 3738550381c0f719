"""`itt-planner simulate`: a closed-loop virtual race, replanned vs open loop vs even CP."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from itt_planner.cli._app import JSON_OPTION, app, emit, errors_to_exit, progress_enabled


def _human(r: dict[str, Any]) -> str:
    lines = [(f"{r['course']} / {r['rider']} / {r['scenario']} (seed {r['seed']}): "
              f"full-course optimum {r['plan_finish_time_s']:.1f} s")]
    for policy in ("replanned", "open_loop", "even_cp"):
        p = r[policy]
        lines.append(f"  {policy:10s} finish {p['finish_time_s']:8.1f} s   "
                     f"W' min {p['w_prime_min_j'] / 1000:5.1f} kJ   "
                     f"W' end {p['w_prime_end_j'] / 1000:5.1f} kJ")
    m, lat = r["margins"], r["replan_latency_s"]
    lines.append(f"  replanned is {m['replanned_vs_open_loop_s']:+.1f} s vs open loop, "
                 f"{m['replanned_vs_even_cp_s']:+.1f} s vs even CP, "
                 f"{m['replanned_vs_plan_pct']:+.2f} % vs the optimum")
    lines.append(f"  replan latency median {lat['median'] * 1000:.0f} ms, p95 "
                 f"{lat['p95'] * 1000:.0f} ms, max {lat['max'] * 1000:.0f} ms "
                 f"({r['replans']} replans)")
    return "\n".join(lines)


@app.command("simulate")
def simulate_cli(
    course: str = typer.Option(..., "--course", help="GPS track, saved course, or demo name."),
    rider: str = typer.Option("paper", "--rider", help="Rider preset or YAML file."),
    scenario: str = typer.Option(
        "nominal", "--scenario",
        help="nominal | cp-overestimated | headwind | hot-start"),
    seed: int = typer.Option(0, "--seed", help="Seed of the rider's and sensors' noise."),
    horizon_m: float = typer.Option(1000.0, "--horizon-m", help="Receding horizon (m)."),
    replan_period_s: float = typer.Option(1.0, "--replan-period-s", help="Replan period (s)."),
    cache_dir: Path = typer.Option(Path(".itt_cache"), "--cache-dir",
                                   help="Where full-course plans are cached."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Ride a course in closed loop (3D model in time, noisy sensors, the pacing engine)
    and compare with following the full-course plan blindly and with even CP pacing.
    Plans are solved for the lateral grip the virtual rider uses."""
    from itt_planner.course.loader import load_course  # noqa: PLC0415
    from itt_planner.live.engine import EngineSettings  # noqa: PLC0415
    from itt_planner.model.conditions import Conditions  # noqa: PLC0415
    from itt_planner.model.rider import load_rider  # noqa: PLC0415
    from itt_planner.ocp import (  # noqa: PLC0415
        HorizonPlanner,
        HorizonSettings,
        OcpSettings,
        load_or_solve,
    )
    from itt_planner.sim import compare_policies, planning_conditions  # noqa: PLC0415

    with errors_to_exit(as_json):
        built = load_course(course)
        who = load_rider(rider)
        conditions = Conditions()
        # The optimum for the grip the virtual rider uses (belief = truth in nominal).
        plan = load_or_solve(built, who, planning_conditions(conditions), OcpSettings(), "3d",
                             cache_dir=cache_dir)
        # The replanning rider's horizon planner believes what the plan was solved for.
        planner = HorizonPlanner(built, who, plan, conditions=planning_conditions(conditions),
                                 settings=HorizonSettings(horizon_m=horizon_m))
        result = compare_policies(
            built, who, plan, scenario=scenario, seed=seed, conditions=conditions,
            engine_settings=EngineSettings(replan_period_s=replan_period_s),
            planner=planner, progress=progress_enabled())
        emit(result, as_json, _human)
