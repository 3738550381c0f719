"""`itt-planner import` and `itt-planner replay`: ride files to MCAP logs, logs to advice."""

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
    check_day_air,
    day_conditions,
    emit,
    errors_to_exit,
    progress_enabled,
)


def _human_import(r: dict[str, Any]) -> str:
    lines = [(f"wrote {r['output']}: {r['records']} records, "
              f"{r['duration_s'] / 3600:.2f} h from first to last record")]
    lines += [f"  {topic:24s} {count:7d} messages" for topic, count in r["topics"].items()]
    longest = max((p["duration_s"] for p in r["pauses"]), default=0.0)
    lines.append(f"  {len(r['pauses'])} pauses (longest {longest:.0f} s), "
                 f"{r['recording_gaps']} gaps ridden through (smart recording, missed "
                 f"fixes; longest {r['recording_gap_longest_s']:.0f} s), "
                 f"{r['gps_jumps']} GPS jumps, {r['power_spikes']} power spikes, "
                 f"{r['records_without_position']} records without position "
                 "(all kept as recorded)")
    if r["air_temperature_c"] is not None:
        lines.append(f"  air temperature {r['air_temperature_c']:.1f} C (median of the "
                     "records; replay's --air-temperature-c plans in it)")
    lines += [f"WARNING: {w}" for w in r["warnings"]]
    return "\n".join(lines)


@app.command("import")
def import_cli(
    ride: Path = typer.Argument(
        ..., help="Recorded ride with times: .fit, .gpx, .tcx, .csv, .pwx, a .kml/.kmz gx:Track or "
                  ".geojson (or gzipped: .fit.gz)."),
    output: Path = typer.Option(..., "--output", "-o", help="The MCAP ride log to write."),
    rider: str = typer.Option("", "--rider", help="Rider name for the log's metadata."),
    namespace: str = typer.Option("/itt", "--namespace", help="ROS namespace of the topics."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Write a recorded ride as a ROS 2 MCAP log (GPS, speed, power at the recorded times)."""
    from itt_planner.logs.ride_import import import_ride  # noqa: PLC0415

    with errors_to_exit(as_json):
        emit(import_ride(ride, output, rider=rider, namespace=namespace).as_dict(), as_json,
             _human_import)


def _human_replay(r: dict[str, Any]) -> str:
    lines = [(f"replayed {r['messages_in']} messages ({r['ride_duration_s'] / 60:.1f} min of "
              f"ride) in {r['wall_time_s']:.1f} s: {r['realtime_factor']:.1f}x real time, "
              f"{r['advice_out']} advice ({r['fallbacks']} fallbacks)")]
    lines += [f"  wrote {r[k]}" for k in ("output", "rrd") if r[k]]
    lines += [f"  warning: {w}" for w in r["warnings"]]
    lines += [f"  ERROR: {e}" for e in r["errors"]]
    return "\n".join(lines)


@app.command("replay")
def replay_cli(
    log: Path = typer.Argument(..., help="MCAP ride log (from `itt-planner import` or a bag)."),
    course: str = typer.Option(..., "--course",
                               help="Course: demo name, GPS track or .course.npz."),
    rider: str = typer.Option(..., "--rider", help="Rider preset or rider YAML."),
    out: Path | None = typer.Option(None, "--out",
                                    help="Output MCAP: inputs + advice + diagnostics."),
    rrd: Path | None = typer.Option(None, "--rrd", help="Rerun recording of the replay (.rrd)."),
    rerun: list[str] = typer.Option(
        [], "--rerun", help="Also stream to Rerun live: spawn | connect[:URL] | serve "
                            "(repeatable)."),
    speed: str = typer.Option("max", "--speed", help="'max', or a multiple of real time (1, 10)."),
    replan_period: float = typer.Option(1.0, "--replan-period",
                                        help="Stamp time between replans (s)."),
    horizon_m: float = typer.Option(1000.0, "--horizon-m", help="Receding-horizon length (m)."),
    model: str = typer.Option("3d", "--model", help="Full-course plan model: 3d or 1d."),
    plan: Path | None = typer.Option(
        None, "--plan", help="Saved full-course plan (`plan -o`), as the node's `plan`; "
                             "default: the cache's for this course, rider and day, or solved."),
    resolve_model: str = typer.Option(
        "auto", "--course-resolve-model",
        help="What a re-solve of the rest of the course solves: auto (3d within 20 km of "
             "the finish, 1d-line before or where the 3d fails), 3d, or 1d-line (the 1D "
             "that knows the corners of the plan's line; the 3D where its plan is "
             "refused)."),
    mu: float = MU_OPTION,
    wind_kmh: float = WIND_KMH_OPTION,
    wind_from_deg: float = WIND_FROM_DEG_OPTION,
    air_density_kgpm3: float | None = AIR_DENSITY_OPTION,
    air_temperature_c: float | None = AIR_TEMPERATURE_OPTION,
    cache_dir: Path = typer.Option(Path(".itt_cache"), "--cache-dir",
                                   help="Where full-course plans are cached."),
    live_timing: bool = typer.Option(
        False, "--live-timing",
        help="Judge solver overruns by the wall clock and publish solve times, as live "
             "(the output is then not byte-reproducible)."),
    namespace: str = typer.Option("/itt", "--namespace",
                                  help="ROS namespace of the log's pacing topics."),
    remap: list[str] = typer.Option(
        [], "--remap", help="Read a topic of the log as a pacing topic, as ros2 bag play "
        "--remap: /fix:=/itt/gps/fix (repeatable)."),
    as_json: bool = JSON_OPTION,
) -> None:
    """Replay a ride log through the pacing engine; write advice to MCAP (and Rerun)."""
    from itt_planner.errors import IttError  # noqa: PLC0415
    from itt_planner.live.resolve_model import RESOLVE_MODELS  # noqa: PLC0415
    from itt_planner.session.config import SessionConfig  # noqa: PLC0415
    from itt_planner.session.replay import (  # noqa: PLC0415
        ReplaySettings,
        parse_remap,
        parse_speed,
        replay_ride,
    )

    with errors_to_exit(as_json):
        try:
            settings = ReplaySettings(speed=parse_speed(speed), remap=parse_remap(remap))
        except ValueError as err:
            raise IttError(str(err)) from None
        if resolve_model not in RESOLVE_MODELS:
            raise IttError(f"--course-resolve-model {resolve_model!r}: choose one of "
                           f"{', '.join(RESOLVE_MODELS)}")
        # The session sets the air of a temperature at its course's altitude.
        check_day_air(air_density_kgpm3, air_temperature_c)
        day = day_conditions(mu, wind_kmh, wind_from_deg, air_density_kgpm3)
        config = SessionConfig(course=course, rider=rider, model=model,
                               plan="" if plan is None else str(plan),
                               plan_cache=str(cache_dir), horizon_m=horizon_m,
                               replan_period_s=replan_period, deterministic=not live_timing,
                               course_resolve_model=resolve_model, namespace=namespace,
                               grip_mu=day.mu_x, wind_speed_mps=day.wind_speed_mps,
                               wind_from_rad=day.wind_from_rad,
                               air_density_kgpm3=day.air_density_kgpm3,
                               air_temperature_c=(math.nan if air_temperature_c is None
                                                  else air_temperature_c))
        result = replay_ride(log, config, output=out, rrd=rrd, rerun_sinks=tuple(rerun),
                             settings=settings, progress=progress_enabled()).as_dict()
    emit(result, as_json, _human_replay)
    if result["errors"]:  # damaged input: everything readable was replayed and written
        raise typer.Exit(code=1)
