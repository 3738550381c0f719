"""Benchmark: GPS track -> Course for a 17 km (Bologna TCX) and a 100 km (Sauerland FIT) track.

Run: `.venv/bin/python bench/bench_course.py`. Prints medians of 5 runs of
- the file read (parsers: tcxreader / fitdecode),
- the full fit (`course_fit.fit_course`: cleaning, 3 adaptive spline passes, heading filter,
  altitude, corners),
- a baseline in the same run: ONE plain `scipy.interpolate.make_smoothing_spline` pass on the
  same cleaned points with GCV-chosen smoothing (no adaptivity, no heading filter),
and the ratio fit / baseline. Needs ../shared/data beside the checkout.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy.interpolate import make_smoothing_spline

from itt_planner.course_fit import clean_track, fit_course
from itt_planner.track_files import read_recording

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "rides"
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


def baseline(rec) -> None:  # noqa: ANN001
    """One GCV smoothing spline through the cleaned fixes, curvature from its derivatives."""
    track = clean_track(rec)
    u = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(track.x_m), np.diff(track.y_m)))])
    spl = make_smoothing_spline(u, np.column_stack([track.x_m, track.y_m]))
    ug = np.arange(0.0, u[-1], 1.0)
    d1, d2 = spl.derivative(1)(ug), spl.derivative(2)(ug)
    _ = (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / np.hypot(d1[:, 0], d1[:, 1]) ** 3


def main() -> None:
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
