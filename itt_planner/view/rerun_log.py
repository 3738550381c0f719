"""Log a ride to Rerun: the course, the plan, the sensor inputs, the estimate and the advice.

`RideRecorder` turns the core's types into Rerun archetypes on an explicit
`rr.RecordingStream` (see `itt_planner.view.rerun_sink.open_recording`). The same calls serve
the live node, a replay and a simulated ride; the layout is `rerun_blueprint`.

The timelines and the entity tree are `rerun_paths`; what is logged once (course, road,
plan curves) is `rerun_scene`.

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
from itt_planner.live.samples import GpsFix, Sample
from itt_planner.model.rider import Rider
from itt_planner.model.state import RiderState
from itt_planner.ocp.plan import Plan
from itt_planner.units import MPS_TO_KMH
from itt_planner.view import rerun_paths as paths
from itt_planner.view import rerun_scene as scene
from itt_planner.view.rerun_paths import DISTANCE_TIMELINE, RIDE_TIMELINE
from itt_planner.view.rerun_scene import GREEN, ORANGE, PLAN_SERIES, RED, thin

#: Stamps from this value on are POSIX seconds (after 2001-09-09), below: a relative clock.
POSIX_MIN_S = 1.0e9
#: GPS fixes per map-track segment. Each fix re-logs its segment, so the cost is
#: O(n * TRACK_SEGMENT / 2) points instead of O(n^2) for one growing line.
TRACK_SEGMENT = 60
#: The 3D path and the ride-time plan samples take a point every PATH_STEP_M of s.
PATH_STEP_M = 5.0
#: Horizon lines (logged with every advice) are thinned to this many points.
MAX_HORIZON_POINTS = 100
#: A target-power change this large (W) is an advice change worth a text-log line.
ADVICE_CHANGE_W = 10.0

_TEXT_LEVEL = {Level.OK: rr.TextLogLevel.INFO, Level.WARN: rr.TextLogLevel.WARN,
               Level.ERROR: rr.TextLogLevel.ERROR, Level.STALE: rr.TextLogLevel.WARN}


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
        self.enabled = rr.is_enabled(rec)
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

    # ---- static -------------------------------------------------------------------------
    def log_course(self) -> None:
        """Log what does not change during the ride: course, road, plan, series styles."""
        if not self.enabled:
            return
        with self._lock:
            scene.log_course(self.rec, self.course, self.rider, self.plan)

    def log_notes(self, notes: list[str]) -> None:
        """What the session's set-up assumes that the course says otherwise
        (`RideSession.setup_warnings`): static, so a coach sees it at any time."""
        if not self.enabled or not notes:
            return
        with self._lock:
            self.rec.log(paths.LOG_SESSION, rr.TextLog("\n".join(notes),
                                                      level=rr.TextLogLevel.WARN), static=True)

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
            scene.log_plan(self.rec, self.course, plan)

    # ---- inputs -------------------------------------------------------------------------
    def _bad_input(self, stamp_s: float, what: str, value: float) -> bool:
        """True (counted, and noted in log/inputs) when a sample cannot be plotted."""
        if not self._set_time(stamp_s, self._s_m):
            return True
        if math.isfinite(value):
            return False
        self.skipped_inputs += 1
        self.rec.log(paths.LOG_INPUTS, rr.TextLog(f"{what}: non-finite value {value!r} skipped",
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
                    self.rec.log(paths.LOG_INPUTS, rr.TextLog(
                        f"{type(sample).__name__}: no view for this sample type, not drawn",
                        level=rr.TextLogLevel.WARN))

    # The sample views: called with the lock held, `state` as given to log_sample.
    def _view_gps(self, fix: GpsFix, state: RiderState | None) -> None:
        """A raw GPS fix on the map and on the track."""
        if state is not None and math.isfinite(state.s_m):
            self._s_m = state.s_m
        if (self._bad_input(fix.stamp_s, "gps latitude", fix.lat_deg)
                or self._bad_input(fix.stamp_s, "gps longitude", fix.lon_deg)):
            return
        point = (fix.lat_deg, fix.lon_deg)
        self.rec.log(paths.MAP_GPS, rr.GeoPoints(lat_lon=[point], colors=ORANGE,
                                             radii=rr.components.Radius.ui_points(4.0)))
        segment = self._track.add(point)
        self.rec.log(paths.map_track_segment(self._track.index), rr.GeoLineStrings(
            lat_lon=[segment], colors=ORANGE, radii=rr.components.Radius.ui_points(2.0)))

    def _view_value(self, sample: Any, _state: RiderState | None) -> None:
        """An input sample of one value on its series (`paths.SAMPLE_SERIES`: wheel
        speed in km/h, power in W)."""
        series = paths.SAMPLE_SERIES[type(sample)]
        value = float(getattr(sample, series.field))
        if self._bad_input(sample.stamp_s, series.label, value):
            return
        self.rec.log(series.path, rr.Scalars(value * series.scale))

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
            self.rec.log(paths.MAP_RIDER, rr.GeoPoints(
                lat_lon=scene.lat_lon(self.course, state.s_m, n), colors=RED,
                radii=rr.components.Radius.ui_points(7.0)))
            self.rec.log(paths.WORLD_RIDER, rr.Points3D([[x, y, z + 1.0]], colors=RED, radii=0.8))
            self.rec.log(paths.ELEVATION_RIDER, rr.Scalars(z))
            if math.isfinite(state.w_prime_j):
                self.rec.log(paths.W_PRIME_ACTUAL, rr.Scalars(state.w_prime_j * 1e-3))
            if self._last_path_s is not None and abs(state.s_m - self._last_path_s) < PATH_STEP_M:
                return
            self._last_path_s = state.s_m
            segment = self._path.add((x, y, z + 0.1))
            self.rec.log(paths.world_path_segment(self._path.index), rr.LineStrips3D(
                [segment], colors=ORANGE, radii=rr.components.Radius.ui_points(2.5)))
            if self.plan is not None:
                # The plan at the rider, on ride_time only: on distance_m it is the full curve.
                self._set_time(state.stamp_s, None)
                for path, _name, _colour, field, scale in PLAN_SERIES:
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
                (paths.POWER_TARGET, advice.target_power_w, 1.0),
                (paths.W_PRIME_FINISH, advice.w_prime_finish_j, 1e-3),
            ):
                if math.isfinite(value):
                    rec.log(path, rr.Scalars(value * scale))
            if advice.solve_time_s > 0:  # 0: on the plan, held or finished (no solve)
                rec.log(paths.SOLVE_TIME_REPLAN, rr.Scalars(advice.solve_time_s * 1e3))
            lat_lon = np.column_stack([advice.line_lat_deg, advice.line_lon_deg])
            xyz = np.column_stack([advice.line_x_m, advice.line_y_m, advice.line_z_m + 0.1])
            ok = np.isfinite(lat_lon).all(axis=1) & np.isfinite(xyz).all(axis=1)
            if ok.sum() >= 2:
                k = thin(np.flatnonzero(ok), MAX_HORIZON_POINTS)
                colour = RED if advice.fallback else GREEN
                rec.log(paths.MAP_TARGET_LINE, rr.GeoLineStrings(
                    lat_lon=[lat_lon[k]], colors=colour,
                    radii=rr.components.Radius.ui_points(3.0)))
                rec.log(paths.WORLD_TARGET_LINE, rr.LineStrips3D(
                    [xyz[k]], colors=colour, radii=rr.components.Radius.ui_points(3.0)))
            change = self._advice_change(advice)
            if change is not None:
                level = rr.TextLogLevel.WARN if advice.fallback else rr.TextLogLevel.INFO
                rec.log(paths.LOG_ADVICE, rr.TextLog(change, level=level))
            for text, level in self._belief_changes(advice):
                rec.log(paths.LOG_BELIEF, rr.TextLog(text, level=level))
            self._set_time(advice.stamp_s, None)
            cp = (advice.cp_in_use_w if math.isfinite(advice.cp_in_use_w)
                  else self.rider.critical_power_w)
            rec.log(paths.POWER_CRITICAL, rr.Scalars(cp))

    def _belief_changes(self, advice: Advice) -> list[tuple[str, rr.TextLogLevel]]:
        """Text-log lines (and levels) for what changed in the advice's CP in use and plan
        version since the last advice: a refit (WARN), a plan adoption (INFO), or both
        when one advice carries both."""
        cp = advice.cp_in_use_w
        now = (cp, int(advice.plan_version))
        last, self._belief = self._belief, now
        if last is None or not math.isfinite(cp):
            return []
        where = f"at {advice.state.s_m / 1000:.2f} km"
        lines = []
        if math.isfinite(last[0]) and cp != last[0]:
            text = (f"CP in use {last[0]:.0f} -> {cp:.0f} W {where} (refit; see "
                    "itt_planner/rider_model)")
            lines.append((text, rr.TextLogLevel.WARN))
        if now[1] != last[1]:
            text = (f"plan {now[1]} adopted {where} (the rest of the course re-solved for "
                    f"CP {cp:.0f} W)")
            lines.append((text, rr.TextLogLevel.INFO))
        return lines

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
                self.rec.log(paths.LOG_DIAGNOSTICS, rr.TextLog(
                    f"{diag.name}{stale}: {diag.message}{values}",
                    level=_TEXT_LEVEL.get(diag.level, rr.TextLogLevel.WARN)))


#: The view of each input sample type: the samples of one value on their series
#: (`paths.SAMPLE_SERIES`: a new scalar sensor needs no code here), GPS fixes on the map.
_SAMPLE_VIEWS: dict[type, Callable[[RideRecorder, Any, RiderState | None], None]] = {
    GpsFix: RideRecorder._view_gps,
    **dict.fromkeys(paths.SAMPLE_SERIES, RideRecorder._view_value),
}
