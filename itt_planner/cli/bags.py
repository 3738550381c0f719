"""`itt-planner make-bag`: write a simulated demo ride as an MCAP ride log."""

from __future__ import annotations

from pathlib import Path

import typer

from itt_planner.cli._app import JSON_OPTION, app, emit, errors_to_exit


@app.command("make-bag")
def make_bag_cli(
    course: str = typer.Option(..., "--course", help="GPS track, saved course, or demo name."),
    rider: str = typer.Option("typical", "--rider", help="Rider preset or YAML file."),
    output: Path = typer.Option(..., "--output", "-o", help="The .mcap ride log to write."),
    seed: int = typer.Option(0, "--seed", help="Seed of the rider's and sensors' noise."),
    scenario: str = typer.Option("nominal", "--scenario",
                                 help="How the truth differs from the plan: nominal, "
                                      "cp-overestimated, headwind, hot-start."),
    cache_dir: Path = typer.Option(Path(".itt_cache"), "--cache-dir",
                                   help="Where full-course plans are cached."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Simulate a rider following the full-course plan (noisy sensors) and log the ride."""
    from itt_planner.course.loader import load_course  # noqa: PLC0415
    from itt_planner.model.conditions import Conditions  # noqa: PLC0415
    from itt_planner.model.rider import load_rider  # noqa: PLC0415
    from itt_planner.ocp.cache import load_or_solve  # noqa: PLC0415
    from itt_planner.ocp.course_settings import OcpSettings  # noqa: PLC0415
    from itt_planner.sim.demo_bags import record_simulated_ride  # noqa: PLC0415

    with errors_to_exit(as_json):
        built, who = load_course(course), load_rider(rider)
        plan = load_or_solve(built, who, Conditions(), OcpSettings(), "3d", cache_dir=cache_dir)
        summary = record_simulated_ride(built, who, plan, output, seed=seed, scenario=scenario)
        emit(summary.as_dict(), as_json,
             lambda r: f"wrote {r['output']}: {r['messages']} messages, "
                       f"{r['ride_duration_s'] / 60:.1f} min of SIMULATED ride, "
                       f"{r['size_bytes'] / 1e6:.2f} MB")
