"""A synthetic GPS track with known geometry, and how far `fit_course` lands from it.

Shared by tests/course/test_course_fit.py and bench/bench_course.py (the accuracy figures
of bench/RESULTS.md): straights, a 12 m hairpin, an S-bend of 40 m radius and a 90 deg
corner of 25 m, sampled every 5-15 m with Gaussian GPS noise.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pymap3d

from itt_planner.course.fit import fit_course
from itt_planner.course.track_files import Recording

#: (kind, turn in degrees or length in m, radius m): straights, a 12 m hairpin of 180 deg,
#: an S-bend of 40 m radius, a 90 deg corner of 25 m.
LAYOUT = [("straight", 400.0, 0.0), ("arc", 180.0, 12.0), ("straight", 400.0, 0.0),
          ("arc", -90.0, 40.0), ("arc", 90.0, 40.0), ("straight", 400.0, 0.0),
          ("arc", -90.0, 25.0), ("straight", 400.0, 0.0)]

#: One piece of the truth: (kind, start s, end s, radius), metres.
Part = tuple[str, float, float, float]


def true_track(step_m: float = 0.05) -> tuple[np.ndarray, np.ndarray, list[Part]]:
    """The layout integrated at `step_m`: x, y (m) and its pieces along s."""
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


def synthetic_recording(seed: int, sigma_m: float = 3.0) -> tuple[Recording, list[Part], float]:
    """Fixes every 5-15 m along the truth with Gaussian GPS noise, as lat/lon; with the
    truth's pieces and its length (m)."""
    rng = np.random.default_rng(seed)
    x, y, parts = true_track()
    s_true = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    s_list = [0.0]
    while s_list[-1] < s_true[-1]:
        s_list.append(s_list[-1] + rng.uniform(5.0, 15.0))
    s = np.array([*s_list[:-1], s_true[-1]])
    xs = np.interp(s, s_true, x) + rng.normal(0.0, sigma_m, len(s))
    ys = np.interp(s, s_true, y) + rng.normal(0.0, sigma_m, len(s))
    lat, lon, _ = pymap3d.enu2geodetic(xs, ys, np.zeros_like(xs), 45.0, 11.0, 100.0)
    rec = Recording(path=Path(f"synthetic-{seed}.gpx"), sha256="", lat_deg=lat, lon_deg=lon,
                    ele_m=np.full(len(s), 100.0))
    return rec, parts, float(s_true[-1])


def fit_errors(seed: int) -> tuple[float, float, dict[float, list[float]], list[str]]:
    """`fit_course` on seed `seed`: relative length error, smallest radius on a straight,
    relative radius errors per true radius, and the corners' directions."""
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
