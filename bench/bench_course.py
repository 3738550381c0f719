"""Benchmark: GPS track -> Course for a 17 km (Bologna TCX) and a 100 km (Sauerland FIT) track.

Run: `.venv/bin/python -m bench.bench_course`. Prints medians of 5 runs of
- the file read (parsers: tcxreader / fitdecode),
- the full fit (`itt_planner.course.fit.fit_course`: cleaning, 3 adaptive spline passes,
  heading filter, altitude, corners),
- a baseline in the same run: ONE plain `scipy.interpolate.make_smoothing_spline` pass on the
  same cleaned points with GCV-chosen smoothing (no adaptivity, no heading filter),
and the ratio fit / baseline. Needs ../shared/data beside the checkout.

`--accuracy N` instead counts, over seeds 0..N-1 of the synthetic track of
tests/support/synthetic_track.py, how often each of the issue's bars holds for `fit_course`.
`--oracle N` counts the same bars for a fit that knows what the general fit cannot: the
layout (lines and tangent circular arcs in the true order) and the sampler (first and last
fix on the course ends, 5-15 m between fixes). It is the maximum-likelihood estimate under
the simulated 3 m Gaussian noise (scipy least_squares, started at the truth): it uses
strictly more information than a fit of a real track can, so its pass counts are a
reference for what is reachable per seed at this noise (~6.5 s CPU per seed).
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pymap3d
from scipy.interpolate import make_smoothing_spline
from scipy.optimize import least_squares
from support.synthetic_track import LAYOUT, bar_passes, fit_errors, synthetic_recording

from itt_planner.course.fit import fit_course
from itt_planner.course.track_clean import clean_track
from itt_planner.course.track_files import Recording, read_recording

ROOT = Path(__file__).resolve().parents[1]

DATA = ROOT.parent / "shared" / "data" / "rides"
TRACKS = {"17 km (zwift_bologna_tt_virtual.tcx)": DATA / "zwift_bologna_tt_virtual.tcx",
          "100 km (sauerland_2025.fit)": DATA / "sauerland_2025.fit"}
RUNS = 5


def median_s(fn: Callable[[], object]) -> float:
    times = []
    for _ in range(RUNS):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def baseline(rec: Recording) -> None:
    """One GCV smoothing spline through the cleaned fixes, curvature from its derivatives."""
    track = clean_track(rec)
    u = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(track.x_m), np.diff(track.y_m)))])
    spl = make_smoothing_spline(u, np.column_stack([track.x_m, track.y_m]))
    ug = np.arange(0.0, u[-1], 1.0)
    d1, d2 = spl.derivative(1)(ug), spl.derivative(2)(ug)
    _ = (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / np.hypot(d1[:, 0], d1[:, 1]) ** 3


def accuracy(n_seeds: int) -> None:
    """Per-bar pass counts of `fit_course` on the synthetic track, seeds 0..n_seeds-1."""
    count = dict.fromkeys(["R12", "R40", "R25", "length", "straights", "all"], 0)
    for seed in range(n_seeds):
        length_err, straight, errors, _ = fit_errors(seed)
        for key, value in bar_passes(length_err, straight, errors).items():
            count[key] += value
    print(f"fit_course, seeds 0-{n_seeds - 1} (R40 counts both S-bend arcs): {count}")


# ---- oracle: the layout and the sampler known, maximum likelihood ------------------------
# Unknowns: start pose, then per LAYOUT piece a length (straight; the last one closes the
# total) or a radius and a signed turn (arc), then the along-track gap of each fix pair.
N_GEOMETRY = sum(1 if kind == "straight" else 2 for kind, _, _ in LAYOUT) - 1


def _oracle_curve(p: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x, y, th = p[0], p[1], p[2]
    geo, total = p[3:3 + N_GEOMETRY], float(p[3 + N_GEOMETRY:].sum())
    xs, ys = np.empty(len(s)), np.empty(len(s))
    k, s0 = 0, 0.0
    for i, (kind, _, _) in enumerate(LAYOUT):
        last = i == len(LAYOUT) - 1
        if kind == "straight":
            length = total - s0 if last else geo[k]
            k += 0 if last else 1
            m = (s >= s0) if last else (s >= s0) & (s < s0 + length)
            xs[m] = x + (s[m] - s0) * math.cos(th)
            ys[m] = y + (s[m] - s0) * math.sin(th)
            x, y = x + length * math.cos(th), y + length * math.sin(th)
        else:
            radius, turn = geo[k], geo[k + 1]
            k += 2
            length, sign = abs(radius * turn), math.copysign(1.0, turn)
            m = (s >= s0) & (s < s0 + length)
            cx, cy = x - sign * radius * math.sin(th), y + sign * radius * math.cos(th)
            ang = th + sign * (s[m] - s0) / radius
            xs[m], ys[m] = cx + sign * radius * np.sin(ang), cy - sign * radius * np.cos(ang)
            th += turn
            x, y = cx + sign * radius * math.sin(th), cy - sign * radius * math.cos(th)
        s0 += length
    return xs, ys


def _oracle_residual(p: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    s = np.concatenate([[0.0], np.cumsum(p[3 + N_GEOMETRY:])])
    cx, cy = _oracle_curve(p, s)
    return np.concatenate([x - cx, y - cy])


def _oracle_jacobian(p: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Geometry columns by central differences; a gap moves every later fix's curve point
    along the tangent there."""
    n = len(x)
    jac = np.zeros((2 * n, len(p)))
    for k in range(3 + N_GEOMETRY):
        step = 1e-6 * max(1.0, abs(p[k]))
        hi, lo = p.copy(), p.copy()
        hi[k] += step
        lo[k] -= step
        jac[:, k] = (_oracle_residual(hi, x, y) - _oracle_residual(lo, x, y)) / (2 * step)
    s = np.concatenate([[0.0], np.cumsum(p[3 + N_GEOMETRY:])])
    x1, y1 = _oracle_curve(p, s + 1e-4)
    x0, y0 = _oracle_curve(p, np.maximum(s - 1e-4, 0.0))
    later = np.tril(np.ones((n, n - 1)), -1)
    jac[:n, 3 + N_GEOMETRY:] = -((x1 - x0) / 2e-4)[:, None] * later
    jac[n:, 3 + N_GEOMETRY:] = -((y1 - y0) / 2e-4)[:, None] * later
    return jac


def oracle(n_seeds: int) -> None:
    """Per-bar pass counts of the maximum-likelihood layout fit, seeds 0..n_seeds-1."""
    count = dict.fromkeys(["R12", "R40", "R25", "length", "all"], 0)
    for seed in range(n_seeds):
        rec, _, true_length = synthetic_recording(seed)
        x, y, _ = pymap3d.geodetic2enu(rec.lat_deg, rec.lon_deg, np.zeros(len(rec)),
                                       45.0, 11.0, 100.0)
        geo: list[float] = []
        lo: list[float] = []
        hi: list[float] = []
        for i, (kind, value, radius) in enumerate(LAYOUT):
            if kind == "straight" and i < len(LAYOUT) - 1:
                geo, lo, hi = [*geo, value], [*lo, 0.0], [*hi, np.inf]
            elif kind == "arc":
                turn = math.radians(value)
                geo += [radius, turn]
                lo += [1.0, min(0.0, 2 * turn)]
                hi += [np.inf, max(0.0, 2 * turn)]
        gaps = np.clip(np.hypot(np.diff(x), np.diff(y)), 5.01, 14.99)
        gaps = np.clip(gaps * true_length / gaps.sum(), 5.01, 14.99)
        p0 = np.concatenate([[x[0], y[0], 0.0], geo, gaps])
        bounds = (np.concatenate([[-np.inf] * 3, lo, np.full(len(gaps), 5.0)]),
                  np.concatenate([[np.inf] * 3, hi, np.full(len(gaps), 15.0)]))
        p = least_squares(_oracle_residual, p0, jac=_oracle_jacobian, bounds=bounds,
                          args=(x, y), x_scale="jac").x
        geo_fit = p[3:3 + N_GEOMETRY]
        # Radii of the hairpin, the two S-bend arcs and the 25 m corner in the parameter list.
        err = [geo_fit[1] / 12 - 1, geo_fit[4] / 40 - 1, geo_fit[6] / 40 - 1, geo_fit[9] / 25 - 1]
        ok = [bool(abs(e) < 0.25) for e in err]
        length_ok = bool(abs(p[3 + N_GEOMETRY:].sum() / true_length - 1) < 0.005)
        count["R12"] += ok[0]
        count["R40"] += ok[1] + ok[2]
        count["R25"] += ok[3]
        count["length"] += length_ok
        count["all"] += all(ok) and length_ok
    print(f"oracle, seeds 0-{n_seeds - 1} (R40 counts both S-bend arcs): {count}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--accuracy", type=int, metavar="N", help="synthetic-track pass counts")
    parser.add_argument("--oracle", type=int, metavar="N", help="the same for the layout oracle")
    args = parser.parse_args()
    if args.accuracy:
        accuracy(args.accuracy)
    if args.oracle:
        oracle(args.oracle)
    if args.accuracy or args.oracle:
        return
    timing()


def timing() -> None:
    print(f"course building, median of {RUNS} runs")
    print(f"{'track':40s} {'points':>7s} {'read s':>8s} {'fit s':>8s} {'baseline s':>11s} "
          f"{'fit/baseline':>12s} {'km':>7s}")
    for label, path in TRACKS.items():
        rec = read_recording(path)
        t_read = median_s(lambda: read_recording(path))  # noqa: B023
        t_fit = median_s(lambda: fit_course(rec))  # noqa: B023
        t_base = median_s(lambda: baseline(rec))  # noqa: B023
        km = fit_course(rec).length_m / 1000
        print(f"{label:40s} {len(rec):7d} {t_read:8.3f} {t_fit:8.3f} {t_base:11.3f} "
              f"{t_fit / t_base:12.2f} {km:7.2f}")


if __name__ == "__main__":
    main()
