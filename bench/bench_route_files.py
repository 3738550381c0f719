"""Benchmark: courses from route planners' files against the course of the ride itself.

Run: `.venv/bin/python -m bench.bench_route_files [--3d]`. From each ride vendored in
`tests/data/` (St John's, Ardennes: MIT), the routes a planner would export: the ride's
positions simplified by Douglas-Peucker (`gpxpy`'s `simplify`, the tolerance in metres:
points every few metres in bends, one per straight), without stamps; and the same
without altitude. For each it prints the points kept by the cleaning, the course length
and the distance the trimming measures (both against the ride's course), the corners,
the tightest radius, the warnings; then the 1D plan's finish, iterations and CPU (and
the 3D plan's with `--3d`; minutes). The ride's own course is the baseline, in the same run.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import gpxpy.gpx
import numpy as np

from itt_planner.course.fit import fit_course
from itt_planner.course.geometry import Course
from itt_planner.course.track_clean import clean_fixes
from itt_planner.course.track_files import Recording, read_recording
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import PRESETS
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.course_settings import OcpSettings

ROOT = Path(__file__).resolve().parents[1]
RIDES = ("edge810_vector_stjohns_2013.fit", "edge1000_ardennes_2019.fit")
TOLERANCES_M = (2.0, 5.0)


def route(rec: Recording, tolerance_m: float, altitude: bool) -> Recording:
    """The ride's positions as a planner's route: Douglas-Peucker at `tolerance_m`, no
    stamps, speed or power; NaN altitude if not `altitude`."""
    ok = np.isfinite(rec.lat_deg) & np.isfinite(rec.lon_deg)
    seg = gpxpy.gpx.GPXTrackSegment([
        gpxpy.gpx.GPXTrackPoint(float(la), float(lo), float(z) if math.isfinite(z) else None)
        for la, lo, z in zip(rec.lat_deg[ok], rec.lon_deg[ok], rec.ele_m[ok], strict=True)])
    seg.simplify(max_distance=tolerance_m)
    pts = seg.points
    ele = [p.elevation if altitude and p.elevation is not None else math.nan for p in pts]
    return Recording(path=rec.path.with_suffix(f".rdp{tolerance_m:g}.gpx"), sha256=rec.sha256,
                     lat_deg=np.array([p.latitude for p in pts]),
                     lon_deg=np.array([p.longitude for p in pts]), ele_m=np.array(ele))


def row(name: str, rec: Recording, ride: Course | None, with_3d: bool) -> Course:
    track = clean_fixes(rec)
    course = fit_course(rec)
    info = course.summary()
    ref = ride or course
    cells = [name, f"{len(track)}/{len(rec)}",
             f"{course.length_m / 1e3:.2f} ({100 * (course.length_m / ref.length_m - 1):+.2f} %)",
             f"{info['build']['trim']['finish_m'] / course.length_m:.4f}",
             f"{len(course.corners)}", f"{info['min_radius_m']}", f"{len(info['warnings'])}"]
    for model in ("1d", "3d") if with_3d else ("1d",):
        t0 = time.process_time()
        plan = solve_plan(course, PRESETS["typical"], Conditions(), OcpSettings(), model=model)
        cells.append(f"{model} {plan.finish_time_s:.1f} s {plan.status} {plan.iterations} its "
                     f"{time.process_time() - t0:.1f} s CPU")
    print(" | ".join(cells), flush=True)
    return course


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--3d", dest="with_3d", action="store_true", help="also the 3D plans")
    args = parser.parse_args()
    print("file | points kept | course km (vs ride's) | trim distance / course length | "
          "corners | tightest R m | warnings | plans (typical rider)")
    for name in RIDES:
        rec = read_recording(ROOT / "tests" / "data" / name)
        ride = row(name, rec, None, args.with_3d)
        for tol in TOLERANCES_M:
            row(f"  route {tol:g} m", route(rec, tol, altitude=True), ride, args.with_3d)
        row(f"  route {TOLERANCES_M[0]:g} m, no altitude",
            route(rec, TOLERANCES_M[0], altitude=False), ride, args.with_3d)


if __name__ == "__main__":
    main()
