"""Course from a race ride: trimming, standing start, altitude source and checks, width.

The ride is synthetic so the truth is known: a standing start whose wheel sensor reads
0 for 4 s while the bike moves into a 94 deg corner at 58 m, the race, then a post-finish
U-turn and the ride back; the device altitude 80 m low over the last 2 km (issue 14).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from typer.testing import CliRunner

from itt_planner.cli import app
from itt_planner.course.elevation import ElevationOptions
from itt_planner.course.fit import CourseOptions, WidthStretch, fit_course
from itt_planner.course.geometry import GPS_ROAD_WIDTH_M, Course
from itt_planner.course.loader import load_course
from itt_planner.course.track_files import read_recording
from itt_planner.course.trim import CUT_WARN_M, Mark, TrimOptions, TrimReport, parse_mark
from itt_planner.errors import CourseError

LAT0, LON0 = 45.0, 11.0
#: 58 m, the 94 deg corner (R 12 m), 3000 m north, a 90 deg bend (R 30 m), 3000 m east
RACE_M = 58.0 + 12 * math.radians(94.0) + 3000.0 + 30 * math.radians(90.0) + 3000.0


def _line(lead_m: float = 0.0, after_m: float = 400.0) -> tuple[np.ndarray, np.ndarray]:
    """Dense centre line (0.5 m): optional lead-in from the west, the race, run-out, U-turn."""
    pts = [np.column_stack([np.linspace(-lead_m, 58.0, 200), np.zeros(200)])]
    a = np.linspace(-math.pi / 2, -math.pi / 2 + math.radians(94.0), 60)
    pts.append(np.column_stack([58.0 + 12 * np.cos(a), 12.0 + 12 * np.sin(a)]))
    x0, y0 = pts[-1][-1]
    d = np.array([math.cos(math.radians(94.0)), math.sin(math.radians(94.0))])
    pts.append(np.array([x0, y0]) + np.linspace(0, 3000, 3000)[:, None] * d)
    x1, y1 = pts[-1][-1]
    b = np.linspace(math.radians(184.0), math.radians(94.0), 60)  # right bend, R 30 m
    c = np.array([x1, y1]) - 30 * np.array([math.cos(b[0]), math.sin(b[0])])
    pts.append(c + 30 * np.column_stack([np.cos(b), np.sin(b)]))
    x2, y2 = pts[-1][-1]
    e = np.array([math.cos(math.radians(4.0)), math.sin(math.radians(4.0))])
    pts.append(np.array([x2, y2]) + np.linspace(0, 3000 + after_m, 3400)[:, None] * e)
    xe, ye = pts[-1][-1]
    u = np.linspace(-math.pi / 2, math.pi / 2, 40)  # the U-turn, R 6 m, to the left
    n = np.array([-e[1], e[0]])
    pts.append(np.array([xe, ye]) + 6 * n + 6 * (np.sin(u)[:, None] * e - np.cos(u)[:, None] * n))
    xb, yb = pts[-1][-1]
    pts.append(np.array([xb, yb]) - np.linspace(0, 300, 300)[:, None] * e)
    xy = np.vstack(pts)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    return xy, s - lead_m


def ride(tmp_path: Path, *, lead_m: float = 0.0, device_error: bool = True,
         name: str = "race.csv") -> tuple[Path, Path]:
    """A 1 Hz ride CSV (time, speed, altitude) and the route CSV of the race (true altitude)."""
    xy, s = _line(lead_m)
    t = np.arange(0.0, 2000.0)
    v = np.minimum(1.2 * t, 11.0)  # standing start, 11 m/s
    pos = np.cumsum(v) - v[0] - lead_m
    pos = pos[pos <= s[-1]]
    t, v = t[: len(pos)], v[: len(pos)]
    rng = np.random.default_rng(1)
    x = np.interp(pos, s, xy[:, 0]) + rng.normal(0, 1.5, len(pos))
    y = np.interp(pos, s, xy[:, 1]) + rng.normal(0, 1.5, len(pos))
    true_z = 100.0 + 0.02 * np.clip(pos, 0, None)
    err = -80.0 * np.clip((pos - (RACE_M - 2000.0)) / 400.0, 0, 1)
    z = true_z + (err if device_error else 0.0) + rng.normal(0, 0.3, len(pos))
    speed = np.where(t < 4 + lead_m / 11.0, 0.0, v)  # the wheel sensor lags the start
    lat, lon, _ = pymap3d.enu2geodetic(x, y, 0 * x, LAT0, LON0, 0.0)
    path = tmp_path / name
    rows = [f"{a:.8f},{b:.8f},{c:.2f},{1.7e9 + k:.0f},{w:.2f}"
            for a, b, c, k, w in zip(lat, lon, z, t, speed, strict=True)]
    path.write_text("lat,lon,ele,time,speed\n" + "\n".join(rows) + "\n")
    keep = (s >= 0) & (s <= RACE_M)
    rlat, rlon, _ = pymap3d.enu2geodetic(xy[keep, 0][::20], xy[keep, 1][::20], 0.0, LAT0, LON0,
                                         0.0)
    rz = 100.0 + 0.02 * s[keep][::20]
    route = tmp_path / "route.csv"
    route.write_text("lat,lon,ele\n" + "\n".join(
        f"{a:.8f},{b:.8f},{c:.2f}" for a, b, c in zip(rlat, rlon, rz, strict=True)) + "\n")
    return path, route


def big_turns(course: Course) -> list[float]:
    return [math.degrees(c.angle_rad) for c in course.corners if math.degrees(c.angle_rad) > 60]


def test_standing_start_and_post_finish_uturn(tmp_path: Path) -> None:
    path, _ = ride(tmp_path)
    course = fit_course(read_recording(path))
    trim = course.build["trim"]
    assert trim["moving_with_speed_0"] >= 3  # the first seconds are kept...
    first = course.corners[0]
    assert first.apex_s_m < 100.0 and 80 < math.degrees(first.angle_rad) < 110  # ...with the corner
    assert trim["finish_method"] == "u-turn" and trim["cut_after_m"] > 300
    assert all(a < 120 for a in big_turns(course)), big_turns(course)  # no 170 deg "corner"
    assert RACE_M < course.length_m < RACE_M + 400  # cut before the turn (the line: --finish)
    assert course.closed_loop is False


def test_long_heuristic_cuts_are_warnings() -> None:
    """A U-turn's cut of kilometres is a guess the user must see (GoldenCheetah's Boise
    training ride lost its first 2.87 km to a U-turn, said only in the trim's notes); a
    short run-out, an override or a route's cut is not."""
    def report(start_m: float, finish_m: float, how: str) -> TrimReport:
        return TrimReport(ride_length_m=40_000.0, start_m=start_m, finish_m=finish_m,
                          start_method=how, finish_method=how)
    [first, last] = report(2867.0, 37_000.0, "u-turn").warnings()
    assert "first 2.87 km" in first and "--start" in first
    assert "last 3.00 km" in last and "--finish" in last
    assert report(CUT_WARN_M - 1, 40_000.0 - 400.0, "u-turn").warnings() == []
    assert report(2867.0, 37_000.0, "override").warnings() == []
    assert report(2867.0, 37_000.0, "route").warnings() == []


def test_overrides_by_distance_and_time(tmp_path: Path) -> None:
    path, _ = ride(tmp_path)
    rec = read_recording(path)
    by_m = fit_course(rec, options=CourseOptions(trim=TrimOptions(finish=parse_mark("6.05km"))))
    assert by_m.length_m == pytest.approx(6050.0, rel=0.01)  # along the GPS fixes
    assert by_m.build["trim"]["finish_method"] == "override"
    by_t = fit_course(rec, options=CourseOptions(trim=TrimOptions(
        start=parse_mark("0:30"), finish=parse_mark("400s"))))
    assert by_t.build["trim"]["start_elapsed_s"] == pytest.approx(30.0, abs=1.0)
    assert by_t.build["trim"]["finish_elapsed_s"] == pytest.approx(400.0, abs=1.0)
    with pytest.raises(CourseError, match=r"race\.csv: finish 90000 m is outside the ride"):
        fit_course(rec, options=CourseOptions(trim=TrimOptions(finish=Mark(distance_m=9e4))))
    assert parse_mark("auto") is None and parse_mark("850") == Mark(distance_m=850.0)
    with pytest.raises(CourseError, match="expected a distance"):
        parse_mark("ten km")


def test_route_trims_lead_in_and_fixes_the_altitude(tmp_path: Path) -> None:
    path, route_path = ride(tmp_path, lead_m=500.0)
    rec, route = read_recording(path), read_recording(route_path)
    device = fit_course(rec, options=CourseOptions(trim=TrimOptions(route=route),
                                                   elevation=ElevationOptions("device")))
    trim = device.build["trim"]
    assert (trim["start_method"], trim["finish_method"]) == ("route", "route")
    assert trim["start_m"] == pytest.approx(500.0, abs=25.0)
    assert device.length_m == pytest.approx(RACE_M, rel=0.01)
    elev = device.build["elevation"]
    # The device is 80 m low over the last 2 km: flagged twice, by the route and by shape.
    assert elev["disagreement"]["max_m"] > 60
    assert any("disagree" in w for w in device.build["warnings"])
    assert any(f["kind"] == "dip" for f in elev["suspect_grades"]) or \
        np.tan(device.beta_rad).min() < -0.08
    mixed = fit_course(rec, options=CourseOptions(trim=TrimOptions(route=route)))
    assert mixed.build["elevation"]["source"] == "mix"
    grade = np.tan(mixed.beta_rad)
    assert grade.min() > -0.01 and grade.max() < 0.05  # the true 2 % climb, no dip or wall
    assert mixed.build["elevation"]["suspect_grades"] == []


def test_road_width_default_option_and_stretches(tmp_path: Path) -> None:
    path, _ = ride(tmp_path, device_error=False)
    rec = read_recording(path)
    plain = fit_course(rec)
    assert np.allclose(plain.width_left_m + plain.width_right_m, GPS_ROAD_WIDTH_M)
    narrow = fit_course(rec, options=CourseOptions(
        road_width_m=7.0, widths=(WidthStretch(1000.0, 2000.0, 4.0),)))
    w = narrow.width_left_m + narrow.width_right_m
    assert w[narrow.s_m < 990].min() == 7.0
    assert w[(narrow.s_m > 1000) & (narrow.s_m < 2000)].max() == 4.0
    with pytest.raises(CourseError, match="road width"):
        fit_course(rec, options=CourseOptions(road_width_m=-1.0))


def test_gps_course_yaml_and_cli(tmp_path: Path) -> None:
    path, route = ride(tmp_path, lead_m=500.0)
    spec = tmp_path / "race.yaml"
    spec.write_text(f"name: my-itt\ntrack: {path.name}\nroute: {route.name}\nelevation: mix\n"
                    "road_width_m: 7\nwidths:\n  - {from_m: 100, to_m: 300, width_m: 4}\n")
    course = load_course(spec)
    assert course.name == "my-itt" and course.build["trim"]["start_method"] == "route"
    assert (course.width_left_m + course.width_right_m).min() == 4.0
    saved = tmp_path / "c.course.npz"
    runner = CliRunner()
    out = runner.invoke(app, ["course", "save", str(spec), "-o", str(saved), "--json"])
    assert out.exit_code == 0, out.output
    info = json.loads(runner.invoke(app, ["course", "info", str(saved), "--json"]).stdout)
    assert info["build"]["elevation"]["source"] == "mix" and info["road_width_m"] == [4.0, 7.0]
    text = runner.invoke(app, ["course", "info", str(path), "--route", str(route),
                               "--elevation", "device"]).stdout
    assert "race: " in text and "WARNING: device and route altitude disagree" in text
    bad = runner.invoke(app, ["course", "info", "verona-like", "--start", "1km", "--json"])
    assert bad.exit_code == 1 and json.loads(bad.stdout)["type"] == "CourseError"
    spec.write_text(f"track: {path.name}\nwidth: 3\n")
    with pytest.raises(CourseError, match=r"race\.yaml: unknown field"):
        load_course(spec)
