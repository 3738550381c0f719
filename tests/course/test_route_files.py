"""Courses from the files a route planner exports: few points (dense in bends, one per long
straight), no altitude or a constant one, Garmin's course TCX, a route laid on a loop."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from itt_planner.course.elevation import ElevationOptions
from itt_planner.course.fit import CourseOptions, fit_course
from itt_planner.course.loader import load_course
from itt_planner.course.track_clean import CleanSettings, clean_fixes
from itt_planner.course.track_files import Recording, read_recording
from itt_planner.course.trim import TrimOptions
from itt_planner.errors import CourseError
from itt_planner.model.rider import PRESETS
from itt_planner.ocp.course_problem import solve_plan

LAT0, LON0 = 45.4, 11.0
RADIUS_M = 20.0


def _route_xy() -> tuple[np.ndarray, np.ndarray, float]:
    """A map-drawn route: 600 m straight (its two ends only), a 90 deg right bend of
    20 m radius (a point every 5 m), 800 m straight (ends only); and its true length."""
    arc = np.linspace(0.0, math.pi / 2, int(RADIUS_M * math.pi / 2 / 5.0) + 1)
    bend_x, bend_y = 600.0 + RADIUS_M * np.sin(arc), -RADIUS_M * (1 - np.cos(arc))
    x = np.concatenate([[0.0], bend_x, [bend_x[-1]]])
    y = np.concatenate([[0.0], bend_y, [bend_y[-1] - 800.0]])
    return x, y, 600.0 + RADIUS_M * math.pi / 2 + 800.0


def _recording(path: Path, x: np.ndarray, y: np.ndarray, ele: np.ndarray) -> Recording:
    lat, lon, _ = pymap3d.enu2geodetic(x, y, np.zeros_like(x), LAT0, LON0, 0.0)
    return Recording(path=path, sha256="0" * 64, lat_deg=np.asarray(lat, float),
                     lon_deg=np.asarray(lon, float), ele_m=np.asarray(ele, float))


def test_a_route_drawn_on_a_map_keeps_every_point_and_its_length(tmp_path: Path) -> None:
    # Without stamps a 600 m step after 5 m ones looked like a GPS jump, and the bend's
    # first points went as a spike; the 5-fix average of the distance cut the bend.
    x, y, length = _route_xy()
    rec = _recording(tmp_path / "route.gpx", x, y, np.linspace(100.0, 90.0, len(x)))
    track = clean_fixes(rec)
    assert len(track) == len(x)
    assert track.distance_m[-1] == pytest.approx(length, rel=0.002)
    course = fit_course(rec)
    assert course.length_m == pytest.approx(length, rel=0.01)
    assert [c.direction for c in course.corners] == ["right"]
    assert course.corners[0].min_radius_m == pytest.approx(RADIUS_M, rel=0.3)
    assert course.build["trim"]["finish_m"] == pytest.approx(length, rel=0.002)


@pytest.mark.parametrize(("ele", "missing"), [
    (math.nan, "no altitude"), (0.0, "the same altitude (0 m) at every fix")])
def test_a_route_without_altitude_is_flat_and_says_so(tmp_path: Path, ele: float,
                                                      missing: str) -> None:
    x, y, _ = _route_xy()
    rec = _recording(tmp_path / "flat.gpx", x, y, np.full(len(x), ele))
    course = fit_course(rec)
    info = course.summary()
    assert info["build"]["elevation"]["device_altitude"]["missing"] == missing
    assert any("FLAT" in w for w in info["warnings"]), info["warnings"]
    assert info["gain_m"] == 0 and math.copysign(1.0, info["loss_m"]) == 1.0  # never -0
    with pytest.raises(CourseError,
                       match=r"flat\.gpx: elevation source 'device': the track has (no|the same)"):
        fit_course(rec, options=CourseOptions(elevation=ElevationOptions(source="device")))
    # A route with altitude gives the climbs (auto: the route's, not a mix with flat).
    hilly = _recording(tmp_path / "dem.gpx", x, y, np.linspace(100.0, 60.0, len(x)))
    course = fit_course(rec, options=CourseOptions(trim=TrimOptions(route=hilly)))
    elevation = course.build["elevation"]
    assert elevation["source"] == "route" and not course.build["warnings"]
    assert float(course.z_m[0] - course.z_m[-1]) == pytest.approx(40.0, abs=2.0)


def test_a_course_tcx_reads_like_the_gpx_route(tmp_path: Path) -> None:
    points = [(45.40 + 0.001 * i, 11.0 + 0.0005 * i, 100.0 + i) for i in range(6)]
    ns = "http://www.garmin.com/xmlschemas/TrainingCenterDatabase/v2"
    body = "".join(
        f"<Trackpoint><Position><LatitudeDegrees>{lat}</LatitudeDegrees><LongitudeDegrees>"
        f"{lon}</LongitudeDegrees></Position><AltitudeMeters>{ele}</AltitudeMeters>"
        "</Trackpoint>" for lat, lon, ele in points)
    tcx = tmp_path / "course.tcx"
    tcx.write_text(f'<?xml version="1.0"?><TrainingCenterDatabase xmlns="{ns}"><Courses>'
                   f"<Course><Name>ITT</Name><Track>{body}</Track></Course></Courses>"
                   "</TrainingCenterDatabase>")
    gpx = tmp_path / "route.gpx"
    gpx.write_text('<?xml version="1.0"?><gpx version="1.1" creator="test"><rte>' + "".join(
        f'<rtept lat="{lat}" lon="{lon}"><ele>{ele}</ele></rtept>' for lat, lon, ele in points)
        + "</rte></gpx>")
    a, b = read_recording(tcx), read_recording(gpx)
    for field in ("lat_deg", "lon_deg", "ele_m"):
        assert np.array_equal(getattr(a, field), getattr(b, field)), field
    assert a.time_s is None


def test_a_route_laid_on_a_closed_loop_ride(data_file: Callable[[str], Path]) -> None:
    # The ride's own file as the route of its track without altitude: route points at
    # the loop's end land on its start, which made the altitude fit's abscissae repeat
    # (a raw ValueError from SciPy).
    ride = read_recording(data_file("rides/edge810_vector_stjohns_2013.fit"))
    no_altitude = dataclasses.replace(ride, ele_m=np.full(len(ride), math.nan))
    course = fit_course(no_altitude, options=CourseOptions(trim=TrimOptions(route=ride)))
    assert course.closed_loop and course.build["elevation"]["source"] == "route"
    assert course.summary()["gain_m"] == pytest.approx(fit_course(ride).summary()["gain_m"],
                                                       rel=0.05)


def _circuit_xy() -> tuple[np.ndarray, np.ndarray]:
    """A 1.6 km circuit as a planner draws it: a 300 m x 400 m rectangle whose four
    corners are 30 m arcs (a point every 5 m), each straight its two ends only."""
    xs: list[float] = []
    ys: list[float] = []
    for cx, cy, a0 in ((270.0, 30.0, -90.0), (270.0, 370.0, 0.0), (30.0, 370.0, 90.0),
                       (30.0, 30.0, 180.0)):
        a = np.radians(np.linspace(a0, a0 + 90.0, 10))
        xs.extend(cx + 30.0 * np.cos(a))
        ys.extend(cy + 30.0 * np.sin(a))
    return np.array([*xs, xs[0]]), np.array([*ys, ys[0]])  # back on its first point


def test_a_circuit_ridden_for_laps(tmp_path: Path) -> None:
    x, y = _circuit_xy()
    rec = _recording(tmp_path / "circuit.gpx", x, y, 100.0 + 0.01 * (x - 150.0))
    lap = fit_course(rec)
    assert lap.closed_loop and len(lap.corners) == 4
    race = fit_course(rec, options=CourseOptions(laps=3))
    assert race.closed_loop and race.build["laps"]["laps"] == 3
    # Each lap is the loop with its seam (the grid's last point to its first), the race
    # ends where one lap does.
    lap_m = race.build["laps"]["lap_m"]
    seam = math.hypot(lap.x_m[0] - lap.x_m[-1], lap.y_m[0] - lap.y_m[-1])
    assert seam < 2.0  # the fit wraps 5 fixes at least around the seam (9 m off with none)
    assert lap_m == pytest.approx(lap.length_m + seam, abs=0.1)
    assert race.length_m == pytest.approx(3 * lap_m - seam, abs=2.0)
    assert len(race.corners) == 12
    assert float(np.max(np.abs(np.diff(race.theta_rad)))) < 0.1  # no jump at the seams
    at_lap = race.enu_at(lap_m)
    assert math.hypot(at_lap[0] - race.x_m[0], at_lap[1] - race.y_m[0]) < 1.0
    # A GPS-course YAML says `laps:` for plan and replay; a point-to-point track has none.
    rec.path.write_text('<?xml version="1.0"?><gpx version="1.1" creator="t"><rte>' + "".join(
        f'<rtept lat="{la}" lon="{lo}"><ele>{z}</ele></rtept>'
        for la, lo, z in zip(rec.lat_deg, rec.lon_deg, rec.ele_m, strict=True)) + "</rte></gpx>")
    (tmp_path / "race.yaml").write_text("track: circuit.gpx\nlaps: 2\n")
    assert load_course(tmp_path / "race.yaml").length_m == pytest.approx(2 * lap_m - seam,
                                                                         abs=2.0)
    (tmp_path / "half.yaml").write_text("track: circuit.gpx\nlaps: 1.5\n")
    with pytest.raises(CourseError, match=r"half\.yaml: 'laps' must be a whole number"):
        load_course(tmp_path / "half.yaml")
    x2, y2, _ = _route_xy()
    with pytest.raises(CourseError, match="2 laps need a closed loop"):
        fit_course(_recording(tmp_path / "route.gpx", x2, y2, np.zeros(len(x2))),
                   options=CourseOptions(laps=2))
    # The 1D plan of two laps: the flying second lap is faster than the standing first.
    plan = solve_plan(fit_course(rec, options=CourseOptions(laps=2)), PRESETS["typical"],
                      model="1d")
    assert plan.meta["success"], plan.meta["attempts"]
    t_lap = float(np.interp(lap_m, plan.s_m, plan.t_s))
    assert plan.finish_time_s - t_lap < t_lap


@st.composite
def drawn_routes(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, float]:
    """A route as a planner draws it: straights (their two ends only) and bends (a point
    every 5 m on an arc), with its true length."""
    x, y, heading, length = [0.0], [0.0], 0.0, 0.0
    for _ in range(draw(st.integers(3, 8))):
        run = draw(st.floats(100.0, 800.0))
        x.append(x[-1] + run * math.cos(heading))
        y.append(y[-1] + run * math.sin(heading))
        radius = draw(st.floats(10.0, 200.0))
        turn = math.radians(draw(st.floats(30.0, 150.0)) * draw(st.sampled_from((-1, 1))))
        steps = max(1, round(abs(turn) * radius / 5.0))  # >= 5.2 m of arc: no duplicates
        cx = x[-1] - radius * math.sin(heading) * math.copysign(1.0, turn)
        cy = y[-1] + radius * math.cos(heading) * math.copysign(1.0, turn)
        for k in range(1, steps + 1):
            h = heading + turn * k / steps
            x.append(cx + radius * math.sin(h) * math.copysign(1.0, turn))
            y.append(cy - radius * math.cos(h) * math.copysign(1.0, turn))
        heading += turn
        length += run + abs(turn) * radius
    return np.array(x), np.array(y), length


@given(route=drawn_routes())
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_any_drawn_route_keeps_its_points_and_length(route: tuple[np.ndarray, np.ndarray,
                                                                  float]) -> None:
    """Every point kept, the length kept. Not a route that comes back past its start in
    its last 90 m: that is a lap file's overrun, cut by the course fit (the test below;
    Hypothesis drew one such 1,355 m route that passed 13 m from its start and ran on 55 m)."""
    x, y, length = route
    to_end = np.cumsum(np.hypot(np.diff(x), np.diff(y))[::-1])[::-1]
    tail = np.append(to_end <= 3 * CleanSettings().closed_loop_gap_m, True)
    tail[-10:] = True
    assume(np.hypot(x[tail], y[tail]).min() > 3 * CleanSettings().closed_loop_gap_m
           or math.hypot(x[-1], y[-1]) <= CleanSettings().closed_loop_gap_m)
    rec = _recording(Path("drawn.gpx"), x, y, np.zeros(len(x)))
    assert len(clean_fixes(rec)) == len(x)  # no route point taken for a GPS spike
    course = fit_course(rec)
    assert course.length_m == pytest.approx(length, rel=0.03)
    assert course.build["trim"]["finish_m"] == pytest.approx(course.length_m, rel=0.03)


def test_a_route_past_its_start_is_a_lap_with_its_overrun_cut() -> None:
    """A 200 m circle drawn round 380 deg: the last 70 m run on past the start, as a lap
    file's do. The course is the closed lap, and `course info`'s notes say what was cut."""
    h = np.arange(0.0, math.radians(380.0), 5.0 / 200.0)
    rec = _recording(Path("lap.gpx"), 200.0 * np.sin(h), 200.0 * (1.0 - np.cos(h)),
                     np.zeros(len(h)))
    course = fit_course(rec)
    assert course.closed_loop
    assert course.length_m == pytest.approx(2 * math.pi * 200.0, rel=0.01)
    assert any("the last 70 m cut" in note for note in course.build["trim"]["notes"])
