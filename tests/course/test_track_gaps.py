"""Gaps in the fixes (a GPS without sky, a log in several recordings): the course runs
straight across them, keeps its length, and says so."""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from pathlib import Path

import gpxpy
import gpxpy.gpx
import numpy as np
import pymap3d
import pytest
from hypothesis import given
from hypothesis import strategies as st

from itt_planner.course.fit import fit_course_file
from itt_planner.course.geometry import Course
from itt_planner.course.track_gaps import GAP_END_M, GAP_MIN_M, fill_gaps, find_gaps

LAT0, LON0 = 46.0, 14.3
SPEED_MPS = 11.0


def _road(s: np.ndarray) -> np.ndarray:
    """1 km east, a 90 deg left bend of 20 m radius, 3 km north, a right bend of 20 m,
    1 km east: the point at arc length `s`."""
    r, arc = 20.0, 20.0 * np.pi / 2
    legs = [1000.0, arc, 3000.0, arc, 1000.0]
    ends = np.cumsum(legs)
    out = np.empty((len(s), 2))
    for k, si in enumerate(s):
        if si <= ends[0]:
            out[k] = si, 0.0
        elif si <= ends[1]:
            a = (si - ends[0]) / r
            out[k] = 1000.0 + r * np.sin(a), r * (1 - np.cos(a))
        elif si <= ends[2]:
            out[k] = 1000.0 + r, r + si - ends[1]
        elif si <= ends[3]:
            a = (si - ends[2]) / r
            out[k] = 1000.0 + r + r * (1 - np.cos(a)), 3000.0 + r + r * np.sin(a)
        else:
            out[k] = 1000.0 + 2 * r + si - ends[3], 3000.0 + 2 * r
    return out


def _multi_log_gpx(path: Path, gap: tuple[float, float]) -> float:
    """A 1 Hz ride of `_road` with 1 m of GPS noise, written as two <trk> (the device
    off between arc lengths `gap`); returns the road's length."""
    length = 5000.0 + 2 * 20.0 * np.pi / 2
    s = np.arange(0.0, length, SPEED_MPS)
    xy = _road(s) + np.random.default_rng(3).normal(0.0, 1.0, (len(s), 2))
    lat, lon, _ = pymap3d.enu2geodetic(xy[:, 0], xy[:, 1], 0.0, LAT0, LON0, 0.0)
    t0 = dt.datetime(2024, 5, 1, 10, tzinfo=dt.UTC)
    gpx = gpxpy.gpx.GPX()
    for part in (s < gap[0], s > gap[1]):
        seg = gpxpy.gpx.GPXTrackSegment()
        seg.points = [gpxpy.gpx.GPXTrackPoint(float(a), float(b), elevation=300.0,
                                              time=t0 + dt.timedelta(seconds=float(k)))
                      for k, a, b in zip(np.flatnonzero(part), lat[part], lon[part],
                                         strict=True)]
        track = gpxpy.gpx.GPXTrack()
        track.segments.append(seg)
        gpx.tracks.append(track)
    path.write_text(gpx.to_xml())
    return length


def _off_road(course: Course) -> float:
    """The course centre line's largest distance from `_road` (m)."""
    fine = _road(np.arange(0.0, 5063.0, 0.5))
    pts = np.column_stack([course.x_m, course.y_m])[::5]
    return float(max(np.hypot(*(fine - p).T).min() for p in pts))


def test_a_log_in_two_recordings_runs_straight_across_the_gap(tmp_path: Path) -> None:
    """The device off for 1.5 km of the 3 km straight, from 60 m after the first bend to
    60 m before the second: the course stays on the road, keeps the road's length, and the
    gap is listed and warned about. (Before, the spline through the gap's ends swung wide
    of it: its corners' neighbours pulled the curve.)"""
    path = tmp_path / "two_logs.gpx"
    length = _multi_log_gpx(path, (1091.4, 3971.4))
    course = fit_course_file(path)
    assert course.length_m == pytest.approx(length, rel=0.01)
    assert _off_road(course) < 8.0
    gaps = course.build["gaps"]
    assert len(gaps) == 1 and gaps[0]["length_m"] == pytest.approx(2880.0, abs=15.0)
    assert gaps[0]["duration_s"] == pytest.approx(2880.0 / SPEED_MPS, abs=2.0)
    assert any("without a fix" in w for w in course.build["warnings"])
    assert [c.direction for c in course.corners] == ["left", "right"]


def test_the_real_gaps_of_a_ride_are_straight(real_course: Callable[[str], Course]) -> None:
    """Shanghai's stop-and-go ride has 347-648 m with no fix (GPS lost in the city): the
    course keeps to each chord (the spline through their ends was 68-132 m off them).
    Two of the three are a pause (25 min) where the fix jumped."""
    course = real_course("rides/elemnt_shanghai_2019_stopgo.fit")
    gaps = [g for g in course.build["gaps"] if g["length_m"] > 300.0]
    assert len(gaps) == 3, course.build["gaps"]
    for gap in gaps:
        # Beyond GAP_END_M of its ends the curve turns into the road there.
        s = np.arange(gap["at_m"] + GAP_END_M, gap["at_m"] + gap["length_m"] - GAP_END_M, 1.0)
        x, y, _ = course.enu_at(s)
        (ax, bx), (ay, by) = (x[0], x[-1]), (y[0], y[-1])
        off = np.abs((bx - ax) * (ay - y) - (ax - x) * (by - ay)) / np.hypot(bx - ax, by - ay)
        assert off.max() < 10.0, (gap, off.max())
    assert any("without a fix" in w for w in course.build["warnings"])


@given(st.lists(st.floats(1.0, 3000.0), min_size=1, max_size=40),
       st.floats(0.0, np.pi), st.integers(0, 2**31 - 1))
def test_fill_keeps_the_fixes_and_puts_points_on_the_chords(steps: list[float], turn: float,
                                                             seed: int) -> None:
    rng = np.random.default_rng(seed)
    heading = np.cumsum(rng.uniform(-turn, turn, len(steps)))
    xy = np.vstack([[0.0, 0.0], np.cumsum(np.column_stack(
        [np.cos(heading), np.sin(heading)]) * np.array(steps)[:, None], axis=0)])
    u = np.concatenate([[0.0], np.cumsum(steps)])
    u_new, xy_new, at = fill_gaps(u, xy)
    assert len(u_new) >= 5 and np.all(np.diff(u_new) > 0)
    assert np.array_equal(u_new[at], u) and np.array_equal(xy_new[at], xy)
    gaps = {g.fix for g in find_gaps(xy)}
    for i in range(len(u) - 1):
        inner = slice(at[i] + 1, at[i + 1])
        if len(u) >= 5 and i not in gaps:
            assert at[i + 1] == at[i] + 1  # not a gap: left alone
            continue
        a, b = xy[i], xy[i + 1]
        pts, d = xy_new[inner], u_new[inner] - u[i]
        assert np.allclose(pts, a + (b - a) * (d / (u[i + 1] - u[i]))[:, None])
        if len(u) >= 5:
            assert steps[i] > GAP_MIN_M and d.min() >= GAP_END_M - 1e-6
            assert d.max() <= steps[i] - GAP_END_M + 1e-6
