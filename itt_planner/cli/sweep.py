"""`itt-planner sweep` and `itt-planner sweep-report`: scenario sweeps on Ray and their report.

Exit codes of `sweep`: 0 the sweep ran to the end (cases that failed or did not converge
are rows with their status and reason, counted in the output); 1 unusable input (spec,
course, rider, output path) or Ray could not be started or joined.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from itt_planner.cli._app import JSON_OPTION, app, emit, errors_to_exit, progress_enabled


def _human(r: dict[str, Any]) -> str:
    counts = r["counts"]
    lines = [(f"{r['output']}: {r['cases']} cases, {r['already_done']} already recorded, "
              f"{r['solved']} solved in {r['wall_s']:.1f} s ({r['cases_per_min']:.1f}/min on "
              f"{r['workers']} workers, {len(r['nodes'])} node(s))"),
             (f"  converged {counts.get('converged', 0)}, not converged "
              f"{counts.get('not_converged', 0)}, failed {counts.get('failed', 0)}")]
    return "\n".join(lines)


@app.command("sweep")
def sweep_cli(
    spec: Path = typer.Argument(..., help="Sweep spec (YAML): courses, riders, axes."),
    output: Path = typer.Option(..., "--output", "-o",
                                help="Result dataset directory (Parquet parts); resumed if "
                                     "it exists."),
    address: str | None = typer.Option(None, "--address",
                                       help="Join this Ray cluster (host:port); default: a private "
                                            "local instance on 127.0.0.1."),
    workers: int | None = typer.Option(None, "--workers", min=1,
                                       help="Worker actors (default: one per CPU of the cluster)."),
    retry_failed: bool = typer.Option(False, "--retry-failed",
                                      help="Re-run cases recorded as failed or not converged."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Run every case of a sweep spec as Ray tasks, writing results as they finish.

    A case that fails is recorded with its status and reason and the sweep goes on; an
    interrupted sweep run again skips the cases already recorded.
    """
    from dataclasses import asdict  # noqa: PLC0415

    from itt_planner.sweep import load_spec, run_sweep  # noqa: PLC0415

    with errors_to_exit(as_json):
        summary = run_sweep(load_spec(spec), output, address=address, workers=workers,
                            retry_failed=retry_failed, progress=progress_enabled())
        result = {**asdict(summary), "wall_s": round(summary.wall_s, 2),
                  "cases_per_min": round(summary.cases_per_min, 2)}
        emit(result, as_json, _human)


@app.command("sweep-report")
def sweep_report_cli(
    results: Path = typer.Argument(..., help="Result dataset written by `sweep`."),
    output: Path = typer.Option(..., "--output", "-o", help="HTML file to write."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Finish time against wind, the cost of the wet, equipment gains, 3D - 1D (static HTML)."""
    from itt_planner.sweep.report import write_sweep_report  # noqa: PLC0415

    with errors_to_exit(as_json):
        info = write_sweep_report(results, output)
        emit(info, as_json, lambda r: (f"{r['output']}: {r['figures']} figures from "
                                       f"{r['converged']} converged of {r['cases']} cases"))


@app.command("calibrate-many")
def calibrate_many_cli(
    folders: list[Path] = typer.Argument(..., help="One folder of ride files per rider "
                                                    "(the folder name is the rider's)."),
    output: Path = typer.Option(..., "--output", "-o",
                                help="Folder for <rider>.rider.yaml and calibration.json."),
    address: str | None = typer.Option(None, "--address",
                                       help="Join this Ray cluster; default: local on 127.0.0.1."),
    workers: int | None = typer.Option(None, "--workers", min=1,
                                       help="CPUs of the local Ray instance (default: all)."),
    mass_kg: float | None = typer.Option(None, "--mass-kg",
                                         help="Rider + bike mass of every rider "
                                              "(default: estimated)."),
    temperature_c: float | None = typer.Option(None, "--temperature-c",
                                               help="Air temperature (default: the record's)."),
    allow_virtual: bool = typer.Option(False, "--allow-virtual",
                                       help="Fit rides whose speed is simulated anyway."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Calibrate many riders in parallel on Ray (`calibrate` on each folder's rides)."""
    from itt_planner.calibration import CalibrationOptions  # noqa: PLC0415
    from itt_planner.sweep.calibrate_many import calibrate_many  # noqa: PLC0415

    with errors_to_exit(as_json):
        info = calibrate_many(list(folders), output, CalibrationOptions(
            mass_kg=mass_kg, temperature_c=temperature_c, allow_virtual=allow_virtual),
            address=address, workers=workers, progress=progress_enabled())
        emit(info, as_json, _human_calibrations)


def _human_calibrations(r: dict[str, Any]) -> str:
    failed = f"; FAILED {', '.join(r['failed'])}" if r["failed"] else ""
    return f"{r['output']}: {r['fitted']} of {r['riders']} riders fitted in {r['wall_s']} s{failed}"
