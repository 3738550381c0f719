"""`itt-planner report` with a calibrated rider and a ride: its calibration and validation.

A 15-minute piece of the St John's ride (MIT, tests/data/) written as a CSV with time,
speed and power: its course is fitted to it, so the report validates against it without
`--ride`; the rider is calibrated on it (aero and CP fitted, cornering refused: no tight
corner in 6 km). The plan is `support.synthetic_ride.make_plan` on that course (a plan's
figures, not a solve: the test is about the report, the README's solve is the slow test).
"""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from support.real_data import data_path
from support.synthetic_ride import make_plan
from typer.testing import CliRunner

from itt_planner.calibration import CalibrationOptions, calibrate, write_rider
from itt_planner.calibration.report_sections import course_ride
from itt_planner.cli import app
from itt_planner.course.geometry import Course
from itt_planner.course.loader import load_course
from itt_planner.course.track_files import read_recording

ST_JOHNS = "rides/edge810_vector_stjohns_2013.fit"
ARDENNES = "rides/edge1000_ardennes_2019.fit"
#: Seconds of the St John's ride kept (calibration needs 600 s of moving time).
PIECE_S = 900.0
#: (ride CSV, rider YAML, plan) of the `piece` fixture.
Piece = tuple[Path, Path, Path]


def write_piece(src: Path, out: Path, seconds: float) -> Path:
    """The first `seconds` of a ride as CSV (time, lat, lon, ele, speed, power)."""
    rec = read_recording(src)
    assert rec.time_s is not None and rec.speed_mps is not None and rec.power_w is not None
    keep = np.flatnonzero(rec.time_s - rec.time_s[0] <= seconds)

    def text(x: float, fmt: str) -> str:
        return "" if np.isnan(x) else format(x, fmt)

    with out.open("w", newline="", encoding="utf-8") as file:
        rows = csv.writer(file)
        rows.writerow(["time", "lat", "lon", "ele", "speed", "power"])
        rows.writerows([f"{rec.time_s[i]:.1f}", f"{rec.lat_deg[i]:.7f}", f"{rec.lon_deg[i]:.7f}",
                        text(rec.ele_m[i], ".1f"), text(rec.speed_mps[i], ".3f"),
                        text(rec.power_w[i], ".0f")] for i in keep)
    return out


@pytest.fixture(scope="module")
def piece(tmp_path_factory: pytest.TempPathFactory) -> Piece:
    base = tmp_path_factory.mktemp("piece")
    ride = write_piece(data_path(ST_JOHNS), base / "stjohns_15min.csv", PIECE_S)
    course = load_course(str(ride))
    result = calibrate([ride], CalibrationOptions(name="me"), courses=[course])
    rider = write_rider(result, base / "me.yaml")
    plan = make_plan(course).save(base / "me.plan.npz")
    return ride, rider, plan


def report(args: list[str]) -> dict[str, object]:
    out = CliRunner().invoke(app, ["report", *args, "--json"])
    assert out.exit_code == 0, out.output
    payload: dict[str, object] = json.loads(out.stdout)
    return payload


def test_report_shows_the_calibrated_rider_and_the_validation(piece: Piece, tmp_path: Path
                                                               ) -> None:
    ride, rider, plan = piece
    html_path = tmp_path / "report.html"
    payload = report([str(plan), "--course", str(ride), "--rider", str(rider),
                      "-o", str(html_path), "--validate-model", "1d"])
    cal = payload["calibration"]
    assert isinstance(cal, dict)
    assert cal["rides"] == [str(ride)]
    yaml_lines = dict(line.split(": ", 1) for line in rider.read_text().splitlines()
                      if not line.startswith("#"))
    cda = cal["values"]["drag_area_m2"]
    assert f"{cda['value']}" == yaml_lines["drag_area_m2"].split("  #")[0]
    assert "bootstrap" in cda["note"] and "2-parameter model" in \
        cal["values"]["critical_power_w"]["note"]
    assert "cornering" in cal["refusals"]
    val = payload["validation"]
    assert isinstance(val, dict) and val["ride"] == str(ride)  # the course's own ride
    runs = val["physics"]
    assert [r["model"] for r in runs] == ["1d"] * 3
    last = runs[-1]
    # The same ride and rider: the replay of its power lands near its finish.
    assert abs(last["finish_error_pct"]) < 2.0
    assert 0.0 < last["noise_floor_kmh"] < last["mae_kmh"] < 5.0
    assert 0.3 < last["share_within_2kmh"] <= 1.0
    assert val["plans"][0]["ride_moving_s"] == pytest.approx(last["ride_moving_s"], abs=1.0)
    page = html_path.read_text()
    for text in ("Calibrated rider", "Validation against the ride", "noise floor",
                 f"MAE {last['mae_kmh']}", "refused cornering", "per km"):
        assert text in page, text
    # Its figures: ride speed against the models', the plan against the ride.
    assert page.split("Validation against the ride", 1)[1].count("data:image/png") == 2


def test_validation_off_named_or_refused(piece: Piece, tmp_path: Path) -> None:
    ride, rider, plan = piece
    out = str(tmp_path / "r.png")  # the PNG: quicker to draw; the JSON says the same
    off = report([str(plan), "--course", str(ride), "--rider", str(rider), "-o", out,
                  "--no-validate"])
    assert "validation" not in off and "calibration" in off
    # Without --ride, the ride is the course's own file, also once the course is saved.
    course = load_course(str(ride))
    assert course_ride(course) == ride
    assert course_ride(Course.load(course.save(tmp_path / "c.course.npz"))) == ride
    no_power = tmp_path / "track.csv"
    no_power.write_text("\n".join(line.rsplit(",", 1)[0] for line in
                                  ride.read_text().splitlines()), encoding="utf-8")
    result = CliRunner().invoke(app, ["report", str(plan), "--course", str(ride), "--rider",
                                      str(rider), "-o", out, "--ride", str(no_power), "--json"])
    assert result.exit_code == 1
    assert "power" in json.loads(result.stdout)["error"]


@pytest.mark.slow
def test_readme_three_commands(tmp_path: Path) -> None:
    """The README's path from a FIT file: calibrate, plan, report (about 2 minutes)."""
    ride = data_path(ARDENNES)
    exe = [str(Path(sys.executable).parent / "itt-planner")]

    def run(*args: str) -> dict[str, object]:
        done = subprocess.run([*exe, *args, "--json"], cwd=tmp_path, capture_output=True,
                              text=True, check=False)
        assert done.returncode == 0, done.stderr
        payload: dict[str, object] = json.loads(done.stdout)
        return payload

    cal = run("calibrate", str(ride), "-o", "me.yaml")
    run("plan", "--course", str(ride), "--rider", "me.yaml", "--model", "1d", "-o",
        "me.plan.npz")
    rep = run("report", "me.plan.npz", "--course", str(ride), "--rider", "me.yaml", "-o",
              "report.html")
    assert rep["calibration"]["values"]["drag_area_m2"]["value"] == pytest.approx(  # type: ignore[index]
        cal["aero"]["cda_m2"], abs=1e-4)  # type: ignore[index]
    assert rep["calibration"]["plan_rider_differs"] == {}  # type: ignore[index]
    last = rep["validation"]["physics"][-1]  # type: ignore[index]
    assert last["model"] == "3d" and abs(last["finish_error_pct"]) < 1.0
