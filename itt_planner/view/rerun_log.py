"""Log a ride to Rerun: the course, the plan, the sensor inputs, the estimate and the advice.

`RideRecorder` turns the core's types into Rerun archetypes on an explicit
`rr.RecordingStream` (see `itt_planner.view.rerun_sink.open_recording`). The same calls serve
the live node, a replay and a simulated ride; the layout is `rerun_blueprint`.

Timelines:
    ride_time   the message stamps: a timestamp timeline for POSIX stamps (recorded
                rides), a duration timeline for stamps counted from 0 (simulations).
    distance_m  arc length along the course (sequence, whole metres), from the latest
                rider state; the full-course plan curves live only on this timeline.

Entities (display units, at the edge: km/h, degrees, kJ, ms, named in the path):
    map/course                  GeoLineStrings, static: course centre line (EPSG:4326)
    map/plan_line               GeoLineStrings, static: the full-course planned line
    map/gps                     GeoPoints: latest raw GPS fix
    map/track/seg_NNNN          GeoLineStrings: the GPS track, in segments of 60 fixes
    map/rider                   GeoPoints: estimated position (s, n) of the rider
    map/target_line             GeoLineStrings: planned line over the horizon (per advice)
    world                       ViewCoordinates RIGHT_HAND_Z_UP (ENU, metres), static
    world/road                  Mesh3D, static: the road ribbon from w_L(s), w_R(s)
    world/road/edges            LineStrips3D, static: left and right road edges
    world/road/centre           LineStrips3D, static: centre line
    world/plan_line             LineStrips3D, static: the full-course planned line
    world/target_line           LineStrips3D: planned line over the horizon (per advice)
    world/rider                 Points3D: estimated position of the rider
    world/path/seg_NNNN         LineStrips3D: the rider's estimated path (a point per 5 m)
    plots/power/{actual,target,critical,plan}          W ("critical": the CP in use, from
                                                       each advice: refits show as steps)
    plots/speed_kmh/{actual,plan}                      km/h
    plots/w_prime_kj/{actual,finish,plan}              kJ ("finish": projected at the line)
    plots/lean_deg/plan                                deg
    plots/friction_use/plan                            C16 left-hand side (<= 1)
    plots/solve_time_ms/replan                         ms per receding-horizon solve
    elevation/profile           Scalars on distance_m: z(s) of the course
    elevation/rider             Scalars (points): z at the rider's position
    log/advice                  TextLog: advice changes (target, cue, status, fallback)
    log/belief                  TextLog: CP refits and plan adoptions, as the advice
                                reports them (`cp_in_use_w`, `plan_version`)
    log/diagnostics             TextLog: diagnostic changes (solver, inputs, fallbacks)
    log/inputs                  TextLog: inputs the recorder could not plot (NaN, inf)

`*/plan` series hold the full-course plan against distance (one `send_columns` call
each) and, on ride_time, the plan sampled at the rider's position every 5 m. The plan
drawn is the one the recorder was built with until `log_plan` is given the plan in
force after an adoption (the advice names its version; the plan's arrays are not in it).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from typing import Any

import numpy as np
import rerun as rr

from itt_planner.course.geometry import Course
from itt_planner.live.advice import Advice, Cue, Diagnostic, Level
from itt_planner.live.samples import GpsFix, PowerReading, Sample, WheelSpeed
from itt_planner.model.rider import Rider
from itt_planner.model.state import RiderState
from itt_planner.ocp.plan import Plan
from itt_planner.view.rerun_blueprint import (
    DISTANCE_TIMELINE,
    RIDE_TIMELINE,
    default_blueprint,
    fit_map_zoom,
)

#: Stamps from this value on are POSIX seconds (after 2001-09-09), below: a relative clock.
POSIX_MIN_S = 1.0e9
#: GPS fixes per map-track segment. Each fix re-logs its segment, so the cost is
#: O(n * TRACK_SEGMENT / 2) points instead of O(n^2) for one growing line.
TRACK_SEGMENT = 60
#: The 3D path and the ride-time plan samples take a point every PATH_STEP_M of s.
PATH_STEP_M = 5.0
#: Geometry logged once (course, ribbon, plan line) is thinned to this many points.
MAX_STATIC_POINTS = 5000
#: Horizon lines (logged with every advice) are thinned to this many points.
MAX_HORIZON_POINTS = 100
#: A target-power change this large (W) is an advice change worth a text-log line.
ADVICE_CHANGE_W = 10.0
MPS_TO_KMH = 3.6

_GREY = (150, 150, 150)
_ROAD = (90, 90, 95)
_WHITE = (235, 235, 235)
_ORANGE = (255, 140, 0)
_RED = (220, 40, 40)
_BLUE = (40, 120, 255)
_GREEN = (0, 190, 90)
_PURPLE = (160, 80, 220)

_TEXT_LEVEL = {Level.OK: rr.TextLogLevel.INFO, Level.WARN: rr.TextLogLevel.WARN,
               Level.ERROR: rr.TextLogLevel.ERROR, Level.STALE: rr.TextLogLevel.WARN}

# (entity, legend name, colour, plan array, scale from SI to display unit)
_PLAN_SERIES = (
    ("plots/power/plan", "planned", _BLUE, "power_w", 1.0),
    ("plots/speed_kmh/plan", "planned", _BLUE, "v_mps", MPS_TO_KMH),
    ("plots/w_prime_kj/plan", "planned", _BLUE, "w_prime_j", 1e-3),
    ("plots/lean_deg/plan", "planned", _BLUE, "phi_rad", math.degrees(1.0)),
    ("plots/friction_use/plan", "planned", _BLUE, "friction_use", 1.0),
)
_LINE_STYLES = (
    ("plots/power/actual", "actual", _ORANGE),
    ("plots/power/target", "target", _GREEN),
    ("plots/power/critical", "critical power", _RED),
    ("plots/speed_kmh/actual", "actual", _ORANGE),
    ("plots/w_prime_kj/actual", "actual", _ORANGE),
    ("plots/w_prime_kj/finish", "projected at finish", _PURPLE),
    ("plots/solve_time_ms/replan", "solve time", _PURPLE),
    ("elevation/profile", "course", _GREY),
)


def _step(n: int, max_points: int) -> int:
    return max(1, math.ceil(n / max_points))


def _thin(a: np.ndarray, max_points: int) -> np.ndarray:
    """Every k-th element so that at most ~max_points remain, always keeping the last."""
    k = _step(len(a), max_points)
    return a[::k] if (len(a) - 1) % k == 0 else np.concatenate([a[::k], a[-1:]])


class _Trail:
    """A polyline that grows one point at a time, logged as segments of bounded length.

    Re-logging one growing line would cost O(n^2); here only the open segment is re-logged,
    each segment under its own entity so the closed ones stay visible (latest-at).
    """

    def __init__(self, segment_points: int) -> None:
        self._segment_points = segment_points
        self._points: list[tuple[float, ...]] = []
        self.index = 0

    def add(self, point: tuple[float, ...]) -> np.ndarray:
        """Append `point`; return the open segment (index `self.index`) to re-log."""
        if len(self._points) >= self._segment_points:
            # Start the next segment at the last point so the line has no gap.
            self._points = self._points[-1:]
            self.index += 1
        self._points.append(point)
        return np.asarray(self._points)


class RideRecorder:
    """Log one ride to a Rerun recording.

    Every method takes the core's types and never raises on odd values (NaN power, a state
    off the course end): a live ride must not stop because of its visualisation. Methods
    may be called from several threads.

    Args:
        rec: the recording (`open_recording`); the recorder never uses Rerun's global one.
        course: the course the ride is on.
        rider: the rider as first believed (the critical-power line until an advice
            names the CP in use).
        plan: the full-course plan, if any (planned curves and line).
    """

    def __init__(self, rec: rr.RecordingStream, course: Course, rider: Rider,
                 plan: Plan | None) -> None:
        self.rec = rec
        # A disabled recording (the `none` sink) costs nothing: no archetypes are built.
        self.enabled = rec.is_enabled()
        self.course = course
        self.rider = rider
        self.plan = plan
        self._lock = threading.Lock()
        self._s_m: float | None = None
        self._track = _Trail(TRACK_SEGMENT)
        self._path = _Trail(TRACK_SEGMENT)
        self._last_path_s: float | None = None
        self._last_advice: Advice | None = None
        #: (CP in use, plan version) of the last advice: their changes are logged.
        self._belief: tuple[float, int] | None = None
        self._plan_version = 0
        self._diag_seen: dict[str, tuple[Level, str]] = {}
        #: Inputs not plotted because they were not finite or have no view.
        self.skipped_inputs = 0
        #: Sample types without a view already noted in log/inputs.
        self._unviewed: set[type] = set()

    # ---- time ---------------------------------------------------------------------------
    def _set_time(self, stamp_s: float, s_m: float | None) -> bool:
        """Set ride time from a stamp and distance from `s_m` (None: not on distance_m).

        Returns False (and counts a skipped input) when the stamp is not finite.
        """
        if not math.isfinite(stamp_s):
            self.skipped_inputs += 1
            return False
        if stamp_s >= POSIX_MIN_S:
            self.rec.set_time(RIDE_TIMELINE, timestamp=stamp_s)
        else:
            self.rec.set_time(RIDE_TIMELINE, duration=stamp_s)
        if s_m is None or not math.isfinite(s_m):
            self.rec.disable_timeline(DISTANCE_TIMELINE)
        else:
            self.rec.set_time(DISTANCE_TIMELINE, sequence=round(s_m))
        return True

    def _lat_lon(self, s_m: np.ndarray | float, n_m: np.ndarray | float = 0.0) -> np.ndarray:
        x, y, z = self.course.enu_at(s_m, n_m)
        lat, lon, _ = self.course.to_geodetic(x, y, z)
        return np.column_stack([np.atleast_1d(lat), np.atleast_1d(lon)])

    # ---- static -------------------------------------------------------------------------
    def log_course(self) -> None:
        """Log what does not change during the ride: course, road, plan, series styles."""
        if not self.enabled:
            return
        with self._lock:
            self._log_course()

    def _log_course(self) -> None:
        rec, course = self.rec, self.course
        rec.send_recording_name(f"{course.name} / {self.rider.name}")
        # The default layout again, with the map zoomed to fit this course.
        extent = max(np.ptp(course.x_m), np.ptp(course.y_m))
        rec.send_blueprint(default_blueprint(map_zoom=fit_map_zoom(course.origin.lat_deg,
                                                                   float(extent))))
        idx = _thin(np.arange(len(course.s_m)), MAX_STATIC_POINTS)
        s = course.s_m[idx]
        rec.log("map/course", rr.GeoLineStrings(
            lat_lon=[self._lat_lon(s)], radii=rr.components.Radius.ui_points(3.0),
            colors=_GREY), static=True)
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
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
        rec.log("world/road", rr.Mesh3D(vertex_positions=vertices, triangle_indices=tris,
                                        albedo_factor=_ROAD), static=True)
        rec.log("world/road/edges", rr.LineStrips3D([left, right], colors=_WHITE,
                                                    radii=rr.components.Radius.ui_points(1.5)),
                static=True)
        rec.log("world/road/centre", rr.LineStrips3D([centre], colors=_GREY,
                                                     radii=rr.components.Radius.ui_points(0.5)),
                static=True)
        # The profile against distance: one call for the whole array.
        rec.send_columns(
            "elevation/profile",
            indexes=[rr.TimeColumn(DISTANCE_TIMELINE, sequence=np.round(s).astype(np.int64))],
            columns=rr.Scalars.columns(scalars=course.z_m[idx]),
        )
        rec.log("elevation/rider", rr.SeriesPoints(names="rider", colors=_RED,
                                                   marker_sizes=4.0), static=True)
        for path, name, colour in _LINE_STYLES:
            rec.log(path, rr.SeriesLines(names=name, colors=colour), static=True)
        cp = self.rider.critical_power_w
        rec.send_columns(
            "plots/power/critical",
            indexes=[rr.TimeColumn(DISTANCE_TIMELINE, sequence=[0, round(course.length_m)])],
            columns=rr.Scalars.columns(scalars=[cp, cp]),
        )
        if self.plan is not None:
            self._log_plan(self.plan)

    def log_plan(self, plan: Plan, version: int) -> None:
        """A new plan in force (`PacingEngine.plan` after an adoption, `plan_version`):
        its curves replace the old plan's from the rider's position on distance_m, and
        the ride-time samples follow it from now on."""
        if not self.enabled:
            return
        with self._lock:
            if version == self._plan_version:
                return
            self.plan = plan
            self._plan_version = version
            self._log_plan(plan)

    def _log_plan(self, plan: Plan) -> None:
        rec = self.rec
        index = rr.TimeColumn(DISTANCE_TIMELINE, sequence=np.round(plan.s_m).astype(np.int64))
        for path, name, colour, field, scale in _PLAN_SERIES:
            rec.log(path, rr.SeriesLines(names=name, colors=colour), static=True)
            rec.send_columns(path, indexes=[index],
                             columns=rr.Scalars.columns(scalars=getattr(plan, field) * scale))
        k = _thin(np.arange(plan.n_nodes), MAX_STATIC_POINTS)
        rec.log("map/plan_line", rr.GeoLineStrings(
            lat_lon=[self._lat_lon(plan.s_m[k], plan.n_m[k])],
            radii=rr.components.Radius.ui_points(2.0), colors=_BLUE), static=True)
        x, y, z = self.course.enu_at(plan.s_m[k], plan.n_m[k])
        # Lifted a few cm so it is drawn on top of the road surface.
        rec.log("world/plan_line", rr.LineStrips3D(
            [np.column_stack([x, y, z + 0.05])], colors=_BLUE,
            radii=rr.components.Radius.ui_points(1.5)), static=True)

    # ---- inputs -------------------------------------------------------------------------
    def _bad_input(self, stamp_s: float, what: str, value: float) -> bool:
        """True (counted, and noted in log/inputs) when a sample cannot be plotted."""
        if not self._set_time(stamp_s, self._s_m):
            return True
        if math.isfinite(value):
            return False
        self.skipped_inputs += 1
        self.rec.log("log/inputs", rr.TextLog(f"{what}: non-finite value {value!r} skipped",
                                              level=rr.TextLogLevel.WARN))
        return True

    def log_sample(self, sample: Sample, state: RiderState | None = None) -> None:
        """One input sample, drawn by the view `_SAMPLE_VIEWS` holds for its type.

        `state` is the estimate after the sample: it places a GPS fix on distance_m (the
        other samples stay at the position of the last state). A sample type without a
        view is counted in `skipped_inputs` and noted once in log/inputs.
        """
        if not self.enabled:
            return
        view = _SAMPLE_VIEWS.get(type(sample))
        with self._lock:
            if view is not None:
                view(self, sample, state)
            else:
                self.skipped_inputs += 1
                if type(sample) not in self._unviewed and self._set_time(sample.stamp_s,
                                                                         self._s_m):
                    self._unviewed.add(type(sample))
                    self.rec.log("log/inputs", rr.TextLog(
                        f"{type(sample).__name__}: no view for this sample type, not drawn",
                        level=rr.TextLogLevel.WARN))

    # Until the session calls log_sample (issue 16, helper H1): the old entry points.
    def log_gps(self, fix: GpsFix, state: RiderState | None = None) -> None:
        """Deprecated by `log_sample`; removed once the session calls it."""
        self.log_sample(fix, state)

    def log_speed(self, sample: WheelSpeed) -> None:
        """Deprecated by `log_sample`; removed once the session calls it."""
        self.log_sample(sample)

    def log_power(self, sample: PowerReading) -> None:
        """Deprecated by `log_sample`; removed once the session calls it."""
        self.log_sample(sample)

    # The sample views: called with the lock held, `state` as given to log_sample.
    def _view_gps(self, fix: GpsFix, state: RiderState | None) -> None:
        """A raw GPS fix on the map and on the track."""
        if state is not None and math.isfinite(state.s_m):
            self._s_m = state.s_m
        if (self._bad_input(fix.stamp_s, "gps latitude", fix.lat_deg)
                or self._bad_input(fix.stamp_s, "gps longitude", fix.lon_deg)):
            return
        point = (fix.lat_deg, fix.lon_deg)
        self.rec.log("map/gps", rr.GeoPoints(lat_lon=[point], colors=_ORANGE,
                                             radii=rr.components.Radius.ui_points(4.0)))
        segment = self._track.add(point)
        self.rec.log(f"map/track/seg_{self._track.index:04d}", rr.GeoLineStrings(
            lat_lon=[segment], colors=_ORANGE, radii=rr.components.Radius.ui_points(2.0)))

    def _view_speed(self, sample: WheelSpeed, _state: RiderState | None) -> None:
        """Wheel speed (actual), in km/h."""
        if self._bad_input(sample.stamp_s, "wheel speed", sample.speed_mps):
            return
        self.rec.log("plots/speed_kmh/actual", rr.Scalars(sample.speed_mps * MPS_TO_KMH))

    def _view_power(self, sample: PowerReading, _state: RiderState | None) -> None:
        """Pedal power (actual), in W."""
        if self._bad_input(sample.stamp_s, "power", sample.power_w):
            return
        self.rec.log("plots/power/actual", rr.Scalars(sample.power_w))

    # ---- estimate and advice -----------------------------------------------------------
    def log_state(self, state: RiderState) -> None:
        """The rider's estimated position, W' balance and the plan at that position."""
        if not self.enabled:
            return
        with self._lock:
            if not math.isfinite(state.s_m):
                self.skipped_inputs += 1
                return
            if not self._set_time(state.stamp_s, state.s_m):
                return
            self._s_m = state.s_m
            n = state.n_m if math.isfinite(state.n_m) else 0.0
            x, y, z = (float(v) for v in self.course.enu_at(state.s_m, n))
            self.rec.log("map/rider", rr.GeoPoints(
                lat_lon=self._lat_lon(state.s_m, n), colors=_RED,
                radii=rr.components.Radius.ui_points(7.0)))
            self.rec.log("world/rider", rr.Points3D([[x, y, z + 1.0]], colors=_RED, radii=0.8))
            self.rec.log("elevation/rider", rr.Scalars(z))
            if math.isfinite(state.w_prime_j):
                self.rec.log("plots/w_prime_kj/actual", rr.Scalars(state.w_prime_j * 1e-3))
            if self._last_path_s is not None and abs(state.s_m - self._last_path_s) < PATH_STEP_M:
                return
            self._last_path_s = state.s_m
            segment = self._path.add((x, y, z + 0.1))
            self.rec.log(f"world/path/seg_{self._path.index:04d}", rr.LineStrips3D(
                [segment], colors=_ORANGE, radii=rr.components.Radius.ui_points(2.5)))
            if self.plan is not None:
                # The plan at the rider, on ride_time only: on distance_m it is the full curve.
                self._set_time(state.stamp_s, None)
                for path, _name, _colour, field, scale in _PLAN_SERIES:
                    self.rec.log(path, rr.Scalars(float(self.plan.at(field, state.s_m)) * scale))

    def log_advice(self, advice: Advice) -> None:
        """Target power, projections, solve time and the horizon line of one advice."""
        if not self.enabled:
            return
        with self._lock:
            s = advice.state.s_m
            self._s_m = s if math.isfinite(s) else self._s_m
            if not self._set_time(advice.stamp_s, self._s_m):
                return
            rec = self.rec
            for path, value, scale in (
                ("plots/power/target", advice.target_power_w, 1.0),
                ("plots/w_prime_kj/finish", advice.w_prime_finish_j, 1e-3),
                ("plots/solve_time_ms/replan", advice.solve_time_s, 1e3),
            ):
                if math.isfinite(value):
                    rec.log(path, rr.Scalars(value * scale))
            lat_lon = np.column_stack([advice.line_lat_deg, advice.line_lon_deg])
            xyz = np.column_stack([advice.line_x_m, advice.line_y_m, advice.line_z_m + 0.1])
            ok = np.isfinite(lat_lon).all(axis=1) & np.isfinite(xyz).all(axis=1)
            if ok.sum() >= 2:
                k = _thin(np.flatnonzero(ok), MAX_HORIZON_POINTS)
                colour = _RED if advice.fallback else _GREEN
                rec.log("map/target_line", rr.GeoLineStrings(
                    lat_lon=[lat_lon[k]], colors=colour,
                    radii=rr.components.Radius.ui_points(3.0)))
                rec.log("world/target_line", rr.LineStrips3D(
                    [xyz[k]], colors=colour, radii=rr.components.Radius.ui_points(3.0)))
            change = self._advice_change(advice)
            if change is not None:
                level = rr.TextLogLevel.WARN if advice.fallback else rr.TextLogLevel.INFO
                rec.log("log/advice", rr.TextLog(change, level=level))
            belief = self._belief_change(advice)
            if belief is not None:
                rec.log("log/belief", rr.TextLog(belief[0], level=belief[1]))
            self._set_time(advice.stamp_s, None)
            cp = (advice.cp_in_use_w if math.isfinite(advice.cp_in_use_w)
                  else self.rider.critical_power_w)
            rec.log("plots/power/critical", rr.Scalars(cp))

    def _belief_change(self, advice: Advice) -> tuple[str, str] | None:
        """A text-log line (and its level) when the advice's CP in use or plan version
        differs from the last advice's: a refit (WARN) or a plan adoption (INFO)."""
        cp = advice.cp_in_use_w
        now = (cp, int(advice.plan_version))
        last, self._belief = self._belief, now
        if last is None or not math.isfinite(cp):
            return None
        where = f"at {advice.state.s_m / 1000:.2f} km"
        if math.isfinite(last[0]) and cp != last[0]:
            return (f"CP in use {last[0]:.0f} -> {cp:.0f} W {where} (refit; see "
                    "itt_planner/rider_model)", rr.TextLogLevel.WARN)
        if now[1] != last[1]:
            return (f"plan {now[1]} adopted {where} (the rest of the course re-solved for "
                    f"CP {cp:.0f} W)", rr.TextLogLevel.INFO)
        return None

    def _advice_change(self, advice: Advice) -> str | None:
        """A text-log line when the advice changed enough to tell the team car, else None."""
        last = self._last_advice
        changed = (
            last is None
            or advice.fallback != last.fallback
            or advice.solver_status != last.solver_status
            or advice.cue != last.cue
            or abs(advice.target_power_w - last.target_power_w) >= ADVICE_CHANGE_W
        )
        if not changed:
            return None
        self._last_advice = advice
        was = "" if last is None else f" (was {last.target_power_w:.0f} W)"
        finish = advice.predicted_finish_s
        finish_txt = (f"{int(finish // 60)}:{finish % 60:04.1f}" if math.isfinite(finish)
                      else "n/a")
        cue = Cue(advice.cue).name.lower()
        corner = (f", corner in {advice.corner_distance_m:.0f} m at "
                  f"{advice.corner_speed_mps * MPS_TO_KMH:.0f} km/h"
                  if math.isfinite(advice.corner_distance_m) else "")
        return (f"{cue} {advice.target_power_w:.0f} W{was}{corner} at "
                f"{advice.state.s_m / 1000:.2f} km;"
                f" finish {finish_txt}, W' at finish {advice.w_prime_finish_j / 1000:.1f} kJ;"
                f" {advice.solver_status}, {advice.solve_time_s * 1000:.0f} ms"
                + ("; FALLBACK (last good plan)" if advice.fallback else ""))

    def log_diagnostics(self, diags: list[Diagnostic]) -> None:
        """Diagnostics whose level or message changed since the last call (no 1 Hz spam)."""
        if not self.enabled:
            return
        with self._lock:
            for diag in diags:
                key = (diag.level, diag.message)
                if self._diag_seen.get(diag.name) == key:
                    continue
                if not self._set_time(diag.stamp_s, self._s_m):
                    continue
                self._diag_seen[diag.name] = key
                stale = " (stale)" if diag.level == Level.STALE else ""
                values = "".join(f" {k}={v}" for k, v in sorted(diag.values.items()))
                self.rec.log("log/diagnostics", rr.TextLog(
                    f"{diag.name}{stale}: {diag.message}{values}",
                    level=_TEXT_LEVEL.get(diag.level, rr.TextLogLevel.WARN)))


#: The view of each input sample type (a new sensor: one `_view_*` method and one entry).
_SAMPLE_VIEWS: dict[type, Callable[[RideRecorder, Any, RiderState | None], None]] = {
    GpsFix: RideRecorder._view_gps,
    WheelSpeed: RideRecorder._view_speed,
    PowerReading: RideRecorder._view_power,
}
