"""What a ride recording logs once: the course on the map, the 3D road, the elevation
profile, the series styles, and the curves and line of the plan in force.

Also the display constants (colours, the plan series and their scales) the recorder's
per-ride logging shares with it. Entity paths are `rerun_paths`.
"""

from __future__ import annotations

import math

import numpy as np
import rerun as rr

from itt_planner.course.geometry import Course
from itt_planner.model.rider import Rider
from itt_planner.ocp.plan import Plan
from itt_planner.units import MPS_TO_KMH
from itt_planner.view import rerun_paths as paths
from itt_planner.view.rerun_blueprint import default_blueprint, fit_map_zoom
from itt_planner.view.rerun_paths import DISTANCE_TIMELINE

#: Geometry logged once (course, ribbon, plan line) is thinned to this many points.
MAX_STATIC_POINTS = 5000

GREY = (150, 150, 150)
ROAD = (90, 90, 95)
WHITE = (235, 235, 235)
ORANGE = (255, 140, 0)
RED = (220, 40, 40)
BLUE = (40, 120, 255)
GREEN = (0, 190, 90)
PURPLE = (160, 80, 220)

#: (entity, legend name, colour, plan array, scale from SI to display unit)
PLAN_SERIES = (
    # Pedalling only: the plan's braking as power (to -2 kW before a hairpin) would squash
    # the pedalled 0-1 kW that the rider and the target are compared on.
    (paths.POWER_PLAN, "planned (pedalling)", BLUE, "pedal_power_w", 1.0),
    (paths.SPEED_PLAN, "planned", BLUE, "v_mps", MPS_TO_KMH),
    (paths.W_PRIME_PLAN, "planned", BLUE, "w_prime_j", 1e-3),
    (paths.LEAN_PLAN, "planned", BLUE, "phi_rad", math.degrees(1.0)),
    (paths.FRICTION_USE_PLAN, "planned", BLUE, "friction_use", 1.0),
)
#: (entity, legend name, colour) of the other line series.
LINE_STYLES = (
    (paths.POWER_ACTUAL, "actual", ORANGE),
    (paths.POWER_TARGET, "target", GREEN),
    (paths.POWER_CRITICAL, "critical power", RED),
    (paths.SPEED_ACTUAL, "actual", ORANGE),
    (paths.W_PRIME_ACTUAL, "actual", ORANGE),
    (paths.W_PRIME_FINISH, "projected at finish", PURPLE),
    (paths.ELEVATION_PROFILE, "course", GREY),
)


def _step(n: int, max_points: int) -> int:
    return max(1, math.ceil(n / max_points))


def thin(a: np.ndarray, max_points: int) -> np.ndarray:
    """Every k-th element so that at most ~max_points remain, always keeping the last."""
    k = _step(len(a), max_points)
    return a[::k] if (len(a) - 1) % k == 0 else np.concatenate([a[::k], a[-1:]])


def lat_lon(course: Course, s_m: np.ndarray | float, n_m: np.ndarray | float = 0.0
            ) -> np.ndarray:
    """(latitude, longitude) rows of the course points at (s, n)."""
    x, y, z = course.enu_at(s_m, n_m)
    lat, lon, _ = course.to_geodetic(x, y, z)
    return np.column_stack([np.atleast_1d(lat), np.atleast_1d(lon)])


def log_course(rec: rr.RecordingStream, course: Course, rider: Rider, plan: Plan | None
               ) -> None:
    """Log what does not change during the ride: course, road, plan, series styles."""
    rec.send_recording_name(f"{course.name} / {rider.name}")
    # The default layout again, with the map zoomed to fit this course.
    extent = max(np.ptp(course.x_m), np.ptp(course.y_m))
    rec.send_blueprint(default_blueprint(map_zoom=fit_map_zoom(course.origin.lat_deg,
                                                               float(extent))))
    idx = thin(np.arange(len(course.s_m)), MAX_STATIC_POINTS)
    s = course.s_m[idx]
    rec.log(paths.MAP_COURSE, rr.GeoLineStrings(
        lat_lon=[lat_lon(course, s)], radii=rr.components.Radius.ui_points(3.0),
        colors=GREY), static=True)
    rec.log(paths.WORLD, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    left = np.column_stack(course.enu_at(s, course.width_left_m[idx]))
    right = np.column_stack(course.enu_at(s, -course.width_right_m[idx]))
    centre = np.column_stack(course.enu_at(s))
    vertices = np.empty((2 * len(s), 3))
    vertices[0::2], vertices[1::2] = left, right
    # Two triangles per road section between cross sections i and i+1.
    i = np.arange(len(s) - 1)
    tris = np.concatenate([
        np.column_stack([2 * i, 2 * i + 1, 2 * i + 2]),
        np.column_stack([2 * i + 1, 2 * i + 3, 2 * i + 2]),
    ])
    rec.log(paths.ROAD, rr.Mesh3D(vertex_positions=vertices, triangle_indices=tris,
                                  albedo_factor=ROAD), static=True)
    rec.log(paths.ROAD_EDGES, rr.LineStrips3D([left, right], colors=WHITE,
                                              radii=rr.components.Radius.ui_points(1.5)),
            static=True)
    rec.log(paths.ROAD_CENTRE, rr.LineStrips3D([centre], colors=GREY,
                                               radii=rr.components.Radius.ui_points(0.5)),
            static=True)
    # The profile against distance: one call for the whole array.
    rec.send_columns(
        paths.ELEVATION_PROFILE,
        indexes=[rr.TimeColumn(DISTANCE_TIMELINE, sequence=np.round(s).astype(np.int64))],
        columns=rr.Scalars.columns(scalars=course.z_m[idx]),
    )
    rec.log(paths.ELEVATION_RIDER, rr.SeriesPoints(names="rider", colors=RED,
                                                   marker_sizes=4.0), static=True)
    # Points: a solve is an event (advice on the plan solves nothing), not a signal.
    rec.log(paths.SOLVE_TIME_REPLAN, rr.SeriesPoints(names="solve time", colors=PURPLE,
                                                     marker_sizes=2.0), static=True)
    for path, name, colour in LINE_STYLES:
        rec.log(path, rr.SeriesLines(names=name, colors=colour), static=True)
    cp = rider.critical_power_w
    rec.send_columns(
        paths.POWER_CRITICAL,
        indexes=[rr.TimeColumn(DISTANCE_TIMELINE, sequence=[0, round(course.length_m)])],
        columns=rr.Scalars.columns(scalars=[cp, cp]),
    )
    if plan is not None:
        log_plan(rec, course, plan)


def log_plan(rec: rr.RecordingStream, course: Course, plan: Plan) -> None:
    """The plan's curves on distance_m and its line on the map and the road (static: a
    plan adopted later replaces them)."""
    index = rr.TimeColumn(DISTANCE_TIMELINE, sequence=np.round(plan.s_m).astype(np.int64))
    for path, name, colour, field, scale in PLAN_SERIES:
        rec.log(path, rr.SeriesLines(names=name, colors=colour), static=True)
        rec.send_columns(path, indexes=[index],
                         columns=rr.Scalars.columns(scalars=getattr(plan, field) * scale))
    k = thin(np.arange(plan.n_nodes), MAX_STATIC_POINTS)
    rec.log(paths.MAP_PLAN_LINE, rr.GeoLineStrings(
        lat_lon=[lat_lon(course, plan.s_m[k], plan.n_m[k])],
        radii=rr.components.Radius.ui_points(2.0), colors=BLUE), static=True)
    x, y, z = course.enu_at(plan.s_m[k], plan.n_m[k])
    # Lifted a few cm so it is drawn on top of the road surface.
    rec.log(paths.WORLD_PLAN_LINE, rr.LineStrips3D(
        [np.column_stack([x, y, z + 0.05])], colors=BLUE,
        radii=rr.components.Radius.ui_points(1.5)), static=True)
