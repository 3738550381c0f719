"""The distance along a ride's fixes (`Track.distance_m`), which places `--start` /
`--finish` and the trim's report: GPS noise must not add length, nor the smoothing cut
the bends a sparse log passes in a few fixes."""

from __future__ import annotations

import math
from pathlib import Path

import fitdecode
import numpy as np
import pymap3d
import pytest

from itt_planner.course.track_clean import clean_fixes
from itt_planner.course.track_files import Recording, read_recording

LAT0, LON0 = 47.26, 9.04
DATA = Path(__file__).resolve().parents[1] / "data"


def _log(tmp_path: Path, xy: np.ndarray, dt_s: float, noise_m: float) -> Recording:
    """A stamped GPS log of the points `xy` (ENU, m), one fix every `dt_s`, with white
    noise of `noise_m` on each axis (seeded)."""
    xy = xy + np.random.default_rng(7).normal(0.0, noise_m, xy.shape)
    lat, lon, _ = pymap3d.enu2geodetic(xy[:, 0], xy[:, 1], 0.0 * xy[:, 0], LAT0, LON0, 0.0)
    n = len(xy)
    return Recording(path=tmp_path / "log.gpx", sha256="0" * 64, lat_deg=np.asarray(lat),
                     lon_deg=np.asarray(lon), ele_m=np.full(n, 500.0),
                     time_s=1.7e9 + dt_s * np.arange(n))


def _switchbacks(step_m: float, radius_m: float = 15.0, legs: int = 12,
                 leg_m: float = 120.0) -> tuple[np.ndarray, float]:
    """Points every `step_m` along straights joined by 180 deg hairpins of `radius_m`,
    and the path's length."""
    seg = [np.array([0.0, 0.0])]
    heading, pos = 0.0, np.zeros(2)
    path: list[np.ndarray] = []
    for k in range(legs):
        ds = np.arange(step_m, leg_m + 1e-9, step_m)
        d = np.array([math.cos(heading), math.sin(heading)])
        path.append(pos + ds[:, None] * d)
        pos = path[-1][-1]
        turn = 1.0 if k % 2 == 0 else -1.0
        centre = pos + turn * radius_m * np.array([-d[1], d[0]])
        a = np.arange(step_m, math.pi * radius_m, step_m) / radius_m
        start = heading - turn * math.pi / 2
        path.append(centre + radius_m * np.column_stack([np.cos(start + turn * a),
                                                         np.sin(start + turn * a)]))
        pos, heading = path[-1][-1], heading + math.pi
    xy = np.vstack(seg + path)
    return xy, float(np.hypot(*np.diff(xy, axis=0).T).sum())


def test_a_sparse_log_through_hairpins_keeps_its_length(tmp_path: Path) -> None:
    # A fix every 2 s at 6 m/s through 15 m hairpins (a Suunto watch's GPX): an average
    # over 5 fixes spans 48 m, three times the radius, and measured -7.7 % on the real
    # file; the quadratic keeps the bend.
    xy, length = _switchbacks(step_m=12.0)
    track = clean_fixes(_log(tmp_path, xy, dt_s=2.0, noise_m=1.0))
    assert track.distance_m[-1] == pytest.approx(length, rel=0.02)


def test_gps_noise_on_a_straight_adds_little(tmp_path: Path) -> None:
    # 1 Hz at 10 m/s with 2 m of white noise: the raw chords gain ~4 %.
    xy = np.column_stack([np.arange(0.0, 3000.0, 10.0), np.zeros(300)])
    track = clean_fixes(_log(tmp_path, xy, dt_s=1.0, noise_m=2.0))
    chords = float(np.hypot(np.diff(track.x_m), np.diff(track.y_m)).sum())
    assert chords > 1.03 * 2990.0
    assert track.distance_m[-1] == pytest.approx(2990.0, rel=0.012)


def test_the_vendored_ride_measures_what_its_device_measured() -> None:
    path = DATA / "edge810_vector_stjohns_2013.fit"
    with fitdecode.FitReader(str(path)) as fit:
        device = [m.get_value("distance") for m in fit
                  if isinstance(m, fitdecode.FitDataMessage) and m.name == "record"
                  and m.has_field("position_lat") and m.get_value("position_lat") is not None
                  and m.get_value("distance") is not None]
    track = clean_fixes(read_recording(path))
    assert track.distance_m[-1] == pytest.approx(device[-1] - device[0], rel=0.005)
