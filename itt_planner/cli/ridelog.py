"""`itt-planner import` and `itt-planner replay`: ride files to MCAP logs, logs to advice."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from itt_planner.cli._app import JSON_OPTION, app, emit, errors_to_exit, progress_enabled


def _human_import(r: dict[str, Any]) -> str:
    lines = [f"wrote {r['output']}: {r['records']} records, "
             f"{r['duration_s'] / 3600:.2f} h from first to last record"]
    lines += [f"  {topic:24s} {count:7d} messages" for topic, count in r["topics"].items()]
    longest = max((p["duration_s"] for p in r["pauses"]), default=0.0)
    lines.append(f"  {len(r['pauses'])} pauses (longest {longest:.0f} s), "
                 f"{r['gps_jumps']} GPS jumps, {r['power_spikes']} power spikes, "
                 f"{r['records_without_position']} records without position "
                 "(all kept as recorded)")
    return "\n".join(lines)


@app.command("import")
def import_cli(
    ride: Path = typer.Argument(..., help="Recorded ride: .fit, .gpx, .tcx or .csv with times."),
    output: Path = typer.Option(..., "--output", "-o", help="The MCAP ride log to write."),
    rider: str = typer.Option("", "--rider", help="Rider name for the log's metadata."),
    namespace: str = typer.Option("/itt", "--namespace", help="ROS namespace of the topics."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Write a recorded ride as a ROS 2 MCAP log (GPS, speed, power at the recorded times)."""
    from itt_planner.ride_import import import_ride  # noqa: PLC0415

    with errors_to_exit(as_json):
        emit(import_ride(ride, output, rider=rider, namespace=namespace).as_dict(), as_json,
             _human_import)
