"""GPS track -> course: accuracy on a synthetic track with known truth, real tracks, bad input."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pymap3d
import pytest

from itt_planner.course.fit import fit_course, fit_course_file
from itt_planner.course.track_files import Recording
from itt_planner.errors import CourseError

# (kind, turn in degrees or length in m, radius m): straights, a 12 m hairpin of 180 deg,
# an S-bend of 40 m radius, a 90 deg corner of 25 m.
LAYOUT = [("straight", 400.0, 0.0), ("arc", 180.0, 12.0), ("straight", 400.0, 0.0),
          ("arc", -90.0, 40.0), ("arc", 90.0, 40.0), ("straight", 400.0, 0.0),
          ("arc", -90.0, 25.0), ("straight", 400.0, 0.0)]


def _truth(step_m: float = 0.05) -> tuple[np.ndarray, np.ndarray, list[tuple[str, float, float, float]]]:
    theta, x, y, s = 0.0, [0.0], [0.0], 0.0
    parts = []
    for kind, value, radius in LAYOUT:
        length = value if kind == "straight" else abs(math.radians(value)) * radius
        kappa = 0.0 if kind == "straight" else math.copysign(1.0 / radius, value)
        parts.append((kind, s, s + length, radius))
        for _ in range(round(length / step_m)):
            theta += kappa * step_m / 2
            x.append(x[-1] + step_m * math.cos(theta))
            y.append(y[-1] + step_m * math.sin(theta))
            theta += kappa * step_m / 2
        s += length
    return np.array(x), np.array(y), parts


def synthetic_recording(seed: int, sigma_m: float = 3.0) -> tuple[Recording, list, float]:
    """Fixes every 5-15 m along the truth with Gaussian GPS noise, as lat/lon."""
    rng = np.random.default_rng(seed)
    x, y, parts = _truth()
    s_true = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    s = [0.0]
    while s[-1] < s_true[-1]:
        s.append(s[-1] + rng.uniform(5.0, 15.0))
    s = np.array([*s[:-1], s_true[-1]])
    xs = np.interp(s, s_true, x) + rng.normal(0.0, sigma_m, len(s))
    ys = np.interp(s, s_true, y) + rng.normal(0.0, sigma_m, len(s))
    lat, lon, _ = pymap3d.enu2geodetic(xs, ys, np.zeros_like(xs), 45.0, 11.0, 100.0)
    rec = Recording(path=Path(f"synthetic-{seed}.gpx"), sha256="", lat_deg=lat, lon_deg=lon,
                    ele_m=np.full(len(s), 100.0))
    return rec, parts, float(s_true[-1])


SEEDS = range(20)


def _errors(seed: int) -> tuple[float, float, dict[float, list[float]], list[str]]:
    """Length error, smallest straight radius, radius errors per true radius, directions."""
    rec, parts, length = synthetic_recording(seed)
    course = fit_course(rec)
    radius = 1.0 / np.maximum(np.abs(course.kappa_per_m), 1e-12)
    straight = np.inf
    errors: dict[float, list[float]] = {12.0: [], 40.0: [], 25.0: []}
    for kind, start, end, true_radius in parts:
        if kind == "straight":
            # Away from the bends (the smoothing reaches ~50 m), a straight stays straight.
            inner = (course.s_m > start + 50) & (course.s_m < end - 50)
            straight = min(straight, float(radius[inner].min()))
        else:
            near = (course.s_m > start - 20) & (course.s_m < end + 20)
            errors[true_radius].append(float(radius[near].min()) / true_radius - 1.0)
    return course.length_m / length - 1.0, straight, errors, [c.direction for c in course.corners]


def bar_passes(length_err: float, straight: float, errors: dict[float, list[float]]
               ) -> dict[str, int]:
    """The issue's bars on one seed: how many bends of each radius are within 25 % (R40
    has two), length within 0.5 %, straights > 300 m, and `all` = 1 if all of them hold."""
    ok = {r: sum(abs(e) < 0.25 for e in errs) for r, errs in errors.items()}
    bars = {"R12": ok[12.0], "R40": ok[40.0], "R25": ok[25.0],
            "length": int(abs(length_err) < 0.005), "straights": int(straight > 300.0)}
    every = all(ok[r] == len(errs) for r, errs in errors.items())
    return bars | {"all": int(every and bars["length"] and bars["straights"])}


def test_synthetic_track_over_seeds_0_to_19() -> None:
    """Every seed of a fixed block (0-19), no picking.

    The issue's per-seed bar (every corner within 25 %, length within 0.5 %, straights
    > 300 m) is NOT met on every seed, and at 3 m noise with 3-5 fixes per corner it is
    out of statistical reach: the maximum-likelihood fit that KNOWS the layout (lines and
    tangent arcs in the true order) and the sampler (ends, 5-15 m gaps),
    `bench/bench_course.py --oracle`, meets it on 10 of these 20 seeds (hairpin 20/20,
    S-bend arcs 35/40, 25 m corner 13/20, length 17/20) and on 101 of seeds 0-199
    (R25 150/200, S-bend arcs 348/400, length 168/200). `fit_course` (no layout knowledge)
    meets all of it on 5 of 20 (seeds 4, 8, 10, 15, 18): hairpin 20/20, S-bend arcs
    32/40, 25 m corner 14/20, length 14/20, straights 17/20 (`--accuracy 20`); on 61 of
    seeds 0-199 (32 before the corner gate and re-tuning of 2026-11-30, 4 of 0-19).
    Asserted here, each the measured value with a small margin so that a change that
    makes the fit worse fails: on every seed the four bends are found with the right
    directions, the hairpin within 25 % (worst today +24 %, seed 13), the S-bend and the
    25 m corner within 60 % (worst -55 %), the length within 1.2 % (worst -1.03 %), no
    straight below 200 m (worst 250 m); the medians of each bend's error and of the
    length error within the bar; and the per-bar pass counts above as floors.
    """
    lengths = []
    counts = dict.fromkeys(["R12", "R40", "R25", "length", "straights", "all"], 0)
    per_radius: dict[float, list[float]] = {12.0: [], 40.0: [], 25.0: []}
    for seed in SEEDS:
        length_err, straight, errors, directions = _errors(seed)
        assert directions == ["left", "right", "left", "right"], seed
        assert abs(length_err) < 0.012, (seed, length_err)
        assert straight > 200.0, (seed, straight)
        assert all(abs(e) < 0.25 for e in errors[12.0]), (seed, errors)
        assert all(abs(e) < 0.60 for e in errors[40.0] + errors[25.0]), (seed, errors)
        for r, e in errors.items():
            per_radius[r].extend(e)
        lengths.append(abs(length_err))
        for key, value in bar_passes(length_err, straight, errors).items():
            counts[key] += value
    assert all(float(np.median(np.abs(e))) < 0.25 for e in per_radius.values())
    assert float(np.median(lengths)) < 0.005
    floors = {"R12": 20, "R40": 32, "R25": 14, "length": 14, "straights": 17, "all": 5}
    assert all(counts[k] >= v for k, v in floors.items()), counts


def test_tokyo_lap_is_a_closed_loop_of_22_1_km(data_file: Callable[[str], Path]) -> None:
    course = fit_course_file(data_file("courses/tokyo2020_olympic_itt_lap.csv"))
    assert course.closed_loop
    assert course.length_m == pytest.approx(22_100.0, rel=0.01)
    tight = [c for c in course.corners if c.min_radius_m < 50.0]
    # Published: 26 corners under 50 m radius.
    assert 20 <= len(tight) <= 32
    # No artefact where the lap closes: heading and position join up.
    gap = math.hypot(course.x_m[-1] - course.x_m[0], course.y_m[-1] - course.y_m[0])
    assert gap < 2.0
    assert all(c.min_radius_m > 5.0 for c in course.corners)


@pytest.mark.parametrize("name", ["edge810_vector_stjohns_2013.fit", "edge1000_ardennes_2019.fit",
                                  "sauerland_2025.fit", "elemnt_shanghai_2019_stopgo.fit",
                                  "zwift_bologna_tt_virtual.tcx"])
def test_every_ride_gives_plausible_grades(data_file: Callable[[str], Path], name: str) -> None:
    course = fit_course_file(data_file(f"rides/{name}"))
    grade = np.tan(course.beta_rad)
    assert np.all(np.abs(grade) <= 0.25), (grade.min(), grade.max())
    assert course.length_m > 10_000
    assert np.all(np.isfinite(course.kappa_per_m))
    assert np.all(np.diff(course.s_m) > 0)
    # No turn-around a bike cannot ride: a ride that leaves and returns along the same road,
    # or circles at the finish, must not be closed into a loop with a U-turn at the seam.
    assert all(c.min_radius_m > 5.0 for c in course.corners), min(
        c.min_radius_m for c in course.corners)


def test_sauerland_pauses_and_jumps_leave_no_spurious_geometry(
        data_file: Callable[[str], Path]) -> None:
    course = fit_course_file(data_file("rides/sauerland_2025.fit"))
    assert course.length_m == pytest.approx(99_000.0, rel=0.03)
    assert not course.closed_loop


def _write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize(("name", "text", "problem"), [
    ("empty.gpx", "", "empty"),
    ("two.csv", "11.0,45.0,100\n11.001,45.0,100\n", "at least 3"),
    ("nan.csv", "nan,nan,1\nnan,nan,2\nnan,nan,3\nnan,nan,4\n", "usable"),
    ("same.csv", "11.0,45.0,100\n" * 50, "identical"),
    ("bad.gpx", "<gpx><trk><trkseg><trkpt lat='x'", "not a valid GPX"),
    ("bad.fit", "this is not a fit file at all", "not a valid FIT"),
    ("route.kml", "<kml/>", "unknown track format"),
])
def test_bad_input_names_file_and_problem(tmp_path: Path, name: str, text: str,
                                           problem: str) -> None:
    path = _write(tmp_path, name, text)
    with pytest.raises(CourseError, match=problem) as info:
        fit_course_file(path)
    assert name in str(info.value)
