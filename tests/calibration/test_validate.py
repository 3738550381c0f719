"""Validation: the 1D model replaying a ride's power against the ride, the CLI, hold-out."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from support.calibration_ride import calibration_course
from support.real_data import data_path
from typer.testing import CliRunner

from itt_planner.calibration import CalibrationError, CalibrationOptions, calibrate
from itt_planner.calibration.validate import validate_ride
from itt_planner.cli import app
from itt_planner.course.geometry import COURSE_SUFFIX, Course
from itt_planner.model.rider import Rider

ST_JOHNS = "rides/edge810_vector_stjohns_2013.fit"
SAUERLAND = "rides/sauerland_2025.fit"
#: The ride, its course, its calibrated rider and the course saved.
StJohns = tuple[Path, Course, Rider, Path]


@pytest.fixture(scope="module")
def st_johns(tmp_path_factory: pytest.TempPathFactory,
             real_course: Callable[[str], Course]) -> StJohns:
    """The St John's ride (MIT, in tests/data/), its course, its calibrated rider and the
    course saved (`--course` of the CLI tests: the ride's track is fitted once)."""
    path = data_path(ST_JOHNS)  # not the data_file fixture: that one is function-scoped
    course = real_course(ST_JOHNS)
    saved = course.save(tmp_path_factory.mktemp("st_johns") / f"st_johns{COURSE_SUFFIX}")
    return path, course, calibrate([path], CalibrationOptions(), courses=[course]).rider, saved


@pytest.fixture(scope="module")
def st_johns_validation(st_johns: StJohns) -> dict[str, Any]:
    path, course, rider, _ = st_johns
    return validate_ride(path, course, rider, models=("1d",)).figures


def test_same_ride_finish_within_1pct(st_johns_validation: dict[str, Any]) -> None:
    """Calibrated on the same ride, the 1D replay of its power with the ride's braking and
    stops in the day's fitted wind finishes within 1 % of the ride's moving time (issue
    15), on the ride's own altitude (the course is the ride's: `elevation` auto); each of
    the ride's inputs lowers the speed error. The power-only replays do not brake where
    the ride braked (620 m) and finish 1.3-1.5 % early on this profile: within 2 %. (On
    the course fit's profile they were within 1 % because its first 100 m rise 2.6 m
    that the ride's altitude does not show, and the model crawled there for 87 s.)"""
    still, windy, inputs = st_johns_validation["physics"]
    assert (still["conditions"], windy["conditions"]) == ("still air", "day wind")
    assert inputs["conditions"] == "day wind, ride's braking and stops"
    assert st_johns_validation["elevation"]["source"] == "ride"
    assert abs(inputs["finish_error_pct"]) < 1.0, inputs
    for run in (still, windy):
        assert abs(run["finish_error_pct"]) < 2.0, run
    assert inputs["mae_kmh"] < windy["mae_kmh"] < still["mae_kmh"]
    assert inputs["ride_inputs"]["stops"] >= 1 and inputs["ride_inputs"]["braking_m"] > 0
    assert windy["per_km"] and 0 < windy["share_within_2kmh"] <= 1
    assert st_johns_validation["day_wind"]["speed_kmh"] > 0
    assert st_johns_validation["rider_values"]["drag_area_m2"] > 0


def test_ride_altitude_lowers_the_speed_error(st_johns: StJohns,
                                              st_johns_validation: dict[str, Any]) -> None:
    """The ride's own altitude, both laps averaged (`ride_elevation`), against the course
    fit's profile of the same readings: the replay's speed MAE falls (1.91 -> 1.64 km/h)
    and the finish stays within 1 %."""
    path, course, rider, _ = st_johns
    on_course = validate_ride(path, course, rider, models=("1d",), elevation="course").figures
    assert on_course["elevation"] == {"source": "course"}
    own, fitted = st_johns_validation["physics"][-1], on_course["physics"][-1]
    assert own["mae_kmh"] < fitted["mae_kmh"] - 0.15, (own, fitted)
    assert abs(fitted["finish_error_pct"]) < 1.0
    with pytest.raises(CalibrationError, match="elevation 'dem'"):
        validate_ride(path, course, rider, models=("1d",), elevation="dem")


@pytest.mark.xfail(strict=True, reason="NOT MET (issue 15): speed MAE 1.64 km/h (1D, day's "
                   "wind, the ride's braking and stops, on the ride's altitude with both laps "
                   "averaged; 1.91 on the course fit's profile) vs a raw-GPS noise floor of "
                   "0.40 km/h on St John's. Measured (bench/bench_replay_error.py): replays on "
                   "one lap's altitude vs the other's differ by 0.9 km/h MAE; lags, wheels' "
                   "inertia and one wind per 10 min do not close the rest; the error at a "
                   "place correlates 0.13 between the two laps (250 m bins): 0.86 km/h of it "
                   "changes from lap to lap, which no profile or steady wind removes")
def test_same_ride_speed_mae_near_noise_floor(st_johns_validation: dict[str, Any]) -> None:
    windy = st_johns_validation["physics"][-1]
    assert windy["mae_kmh"] <= windy["noise_floor_kmh"] + 1.0, windy


def test_wrong_course_is_refused(st_johns: StJohns) -> None:
    """A ride in Newfoundland against a course in Italy (synthetic: no second fit)."""
    path, _, rider, _ = st_johns
    with pytest.raises(CalibrationError, match="wrong --course"):
        validate_ride(path, calibration_course(), rider, models=("1d",))


@pytest.mark.slow
def test_same_ride_3d_replay(st_johns: StJohns) -> None:
    """The 3D virtual rider pedalling the ride's power in the day's wind, with the ride's
    braking and stops: within 1 % too, and replayed over all but the launches."""
    path, course, rider, _ = st_johns
    figures = validate_ride(path, course, rider).figures
    assert "physics_3d" not in figures, figures.get("physics_3d")
    three_d = figures["physics"][-1]
    assert three_d["model"] == "3d" and abs(three_d["finish_error_pct"]) < 1.0, three_d
    assert three_d["ride_inputs"]["ride_own_m"] < 0.01 * figures["covered_m"]


def test_cli_calibrate_then_validate(st_johns: StJohns, tmp_path: Path) -> None:
    """The README's commands: ride -> rider YAML (+ report) -> validation JSON (+ report)."""
    path, _, _, course = st_johns
    runner = CliRunner()
    rider = tmp_path / "me.yaml"
    out = runner.invoke(app, ["calibrate", str(path), "--course", str(course), "-o", str(rider),
                              "--report", str(tmp_path / "cal.html"), "--json"])
    assert out.exit_code == 0, out.output
    summary = json.loads(out.stdout)
    assert 0.18 <= summary["aero"]["cda_m2"] <= 0.45
    assert (tmp_path / "cal.html").read_text().count("data:image/png") == 3
    out = runner.invoke(app, ["validate", str(path), "--course", str(course), "--rider", str(rider),
                              "--model", "1d", "--report", str(tmp_path / "val.html"), "--json"])
    assert out.exit_code == 0, out.output
    figures = json.loads(out.stdout)
    assert abs(figures["physics"][-1]["finish_error_pct"]) < 1.0
    assert (tmp_path / "val.html").read_text().count("data:image/png") == 1


def test_cli_refusal_is_one_json_error(tmp_path: Path) -> None:
    bad = tmp_path / "track.csv"
    bad.write_text("lon,lat,ele\n10.0,45.0,100\n10.001,45.0,101\n10.002,45.0,102\n")
    out = CliRunner().invoke(app, ["calibrate", str(bad), "--json"])
    assert out.exit_code == 1
    err = json.loads(out.stdout)
    assert err["type"] == "CalibrationError" and "timestamps" in err["error"]


@pytest.mark.slow
def test_holdout_two_rides(data_file: Callable[[str], Path]) -> None:
    """Fit on one real ride, predict the other (out of sample), both ways. The corpus has no
    two rides of one rider (these are two people, 103 and 83 kg): the figures are the
    machinery's, no accuracy bar (St John's from the Sauerland rider: -10.7 %)."""
    rides = [data_file(ST_JOHNS), data_file(SAUERLAND)]
    out = CliRunner().invoke(app, ["validate", *map(str, rides), "--holdout", "--model", "1d",
                                   "--json"])
    assert out.exit_code == 0, out.output
    rows = json.loads(out.stdout)["holdout"]
    assert len(rows) == 2
    for row, held in zip(rows, rides, strict=True):
        assert row["held_out"] == str(held) and str(held) not in row["trained_on"]
        assert np.isfinite(row["finish_error_pct"]) and row["mae_kmh"] > 0, row


def test_cli_elevation_option(st_johns: StJohns) -> None:
    """`validate --elevation` reaches the replays (`course`: the course's own profile, as
    the JSON says) and an unknown source is one JSON error naming it."""
    path, _, _, saved = st_johns
    runner = CliRunner()
    out = runner.invoke(app, ["validate", str(path), "--course", str(saved), "--rider", "paper",
                              "--model", "1d", "--elevation", "course", "--json"])
    assert out.exit_code == 0, out.output
    assert json.loads(out.stdout)["elevation"]["source"] == "course"
    out = runner.invoke(app, ["validate", str(path), "--course", str(saved), "--rider", "paper",
                              "--elevation", "barometer", "--json"])
    assert out.exit_code == 1
    err = json.loads(out.stdout)
    assert err["type"] == "CalibrationError" and "'barometer'" in err["error"]
