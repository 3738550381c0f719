"""Raw GPS fixes -> the usable fixes of a track, in ENU, before any curve is fitted.

Steps (each fix keeps the index of its record, so trimming and elevation can map back
to the ride's times and altitudes):

1. drop fixes without a position, out-of-range coordinates and (0, 0);
2. drop fixes where the rider stands still: device speed near zero AND a GPS-implied speed
   (over +-2 fixes) near zero. Device speed alone is not enough: a wheel sensor reads 0
   for the first seconds of a standing start while the bike already moves (issue 14: a
   FIT's first 4 s were dropped and with them a 94 deg corner at 58 m);
3. project to ENU anchored at the first kept fix (pymap3d);
4. drop pause clusters (fixes closer than `min_step_m` to the last kept one) and GPS
   spikes (a fix, or a short run of fixes, that jumps away and comes back);
5. `close_loop`: detect a closed loop (end within `closed_loop_gap_m` of the start on a
   long track) and cut a lap file's overrun past the line.

Trimming to the race (`course_trim`) runs between 4 and 5.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pymap3d
from scipy.signal import savgol_filter

from itt_planner.course.geometry import GeoOrigin
from itt_planner.course.track_files import Recording
from itt_planner.course.track_gaps import find_gaps
from itt_planner.errors import CourseError

#: A GPS log at 1 Hz has fixes 5-20 m apart at racing speed (`Track.distance_m`).
_DENSE_STEP_M = 25.0


@dataclass(frozen=True)
class CleanSettings:
    """Knobs of the cleaning. Defaults are tuned for 1 Hz bike GPS (3-5 m noise).

    Attributes:
        min_step_m: a fix closer than this to the last kept fix is a pause point.
        stopped_speed_mps: a fix whose device speed is below this is a standstill...
        moving_gps_speed_mps: ... unless the GPS says the bike moves faster than this
            (displacement over +-2 fixes; standing GPS wander stays well below it).
        max_speed_mps: implied speeds above this mark a GPS jump (no bike does 30 m/s on
            a course that matters here; Zwift descents top out below it).
        spike_window, unstamped_spike_window: a jump that comes back within this many
            fixes (without stamps: the second; a route's sparse points can close a whole
            lap within the first) is a spike and is removed; one that does not is a real
            gap and is kept.
        closed_loop_gap_m: a track that ends this close to its start is a closed loop...
        closed_loop_min_length_m: ... if it is at least this long.
    """

    min_step_m: float = 2.0
    stopped_speed_mps: float = 0.5
    moving_gps_speed_mps: float = 1.5
    max_speed_mps: float = 30.0
    spike_window: int = 30
    unstamped_spike_window: int = 3
    closed_loop_gap_m: float = 30.0
    closed_loop_min_length_m: float = 1000.0


@dataclass(frozen=True, eq=False)
class Track:
    """Cleaned ENU fixes (m) with the geodetic origin and the closed-loop flag.

    Attributes:
        index: the record index (in the `Recording`) of each fix.
        moving_speed0: fixes kept although the device speed read ~0 (the GPS moved).
        repeated: records dropped as a copy of an earlier one (the same time and place: a
            device that wrote a stretch twice, files joined with an overlap).
        loop_overrun_m: distance cut past the start line of a closed loop (a lap file
            that runs on past the line; `close_loop`).
        altitude_share: the share of the fixes with a recorded altitude (the others are
            interpolated; none at all gives a flat `z_m`, which `course_elevation` reports).
        stamped: the fixes have times (a GPS log), not only positions (a route).
    """

    x_m: np.ndarray
    y_m: np.ndarray
    z_m: np.ndarray
    origin: GeoOrigin
    closed_loop: bool
    index: np.ndarray
    moving_speed0: int = 0
    repeated: int = 0
    loop_overrun_m: float = 0.0
    altitude_share: float = 1.0
    stamped: bool = True

    def __len__(self) -> int:
        return len(self.x_m)

    def notes(self) -> list[str]:
        """What the cleaning kept or dropped that a user should know (`course info`)."""
        notes = []
        if self.moving_speed0:
            notes.append(f"{self.moving_speed0} fixes kept although the device speed read 0: "
                         "the GPS moved (a wheel sensor lags a standing start)")
        if self.repeated:
            notes.append(f"{self.repeated} records dropped: copies of earlier ones (the same "
                         "time and place)")
        if self.loop_overrun_m:
            notes.append(f"the last {self.loop_overrun_m:.0f} m cut: they run on past the "
                         "start line of a closed loop (a lap file's overrun)")
        return notes

    def take(self, sel: np.ndarray | slice) -> Track:
        """The fixes selected by a mask, index array or slice (same origin, not closed)."""
        return replace(self, x_m=self.x_m[sel], y_m=self.y_m[sel], z_m=self.z_m[sel],
                       index=self.index[sel], closed_loop=False)

    @property
    def distance_m(self) -> np.ndarray:
        """Cumulative distance along the fixes (m), 0 at the first.

        Measured on positions smoothed by a quadratic over 5 fixes (Savitzky-Golay) when
        they are a dense GPS log: summed raw steps gain ~sigma^2/step per fix from GPS
        noise, the smoothed ~1/5 of it, and a local quadratic keeps a bend's curvature
        where a plain average over 5 fixes cuts it. The plain average measured a Suunto
        watch's 8.55 km of 2 s fixes through 15-20 m hairpins (its own distance 8.55 km)
        as 7.89 km (-7.7 %); the quadratic 8.51 km. Against the devices' distances it
        is -0.2 % to +0.9 % on the real rides of `../shared/data` (Ardennes +0.09 %, St
        John's +0.21 %, Zwift Bologna -0.24 %, Sauerland +0.85 %); a stop-go city ride's
        standing wander adds more (Shanghai +2.5 %, the average +1.7 %). Other fixes are
        summed as they are: a route (no stamps: drawn on a map, points every few metres in
        bends and one per straight) has no noise to remove, and in a sparse log (median
        step `_DENSE_STEP_M` or more: a fix every few seconds) the gain is small against
        the step. Nor is the smoothing taken across a gap (`track_gaps`): a GPS log of
        four recordings with 1.4-5.4 km between them measured 9.5 km for 11.4 km of chords.
        """
        x, y = self.x_m, self.y_m
        if (self.stamped and len(x) > 1
                and np.median(np.hypot(np.diff(x), np.diff(y))) < _DENSE_STEP_M):
            runs = [g.fix + 1 for g in find_gaps(np.column_stack([x, y]))]
            x, y = (np.concatenate([_smoothed(part) for part in np.split(a, runs)])
                    for a in (x, y))
        return np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])


def _smoothed(a: np.ndarray) -> np.ndarray:
    """A run of fixes' coordinate smoothed by a quadratic over 5 fixes (`Track.distance_m`);
    a run shorter than that as it is."""
    return savgol_filter(a, 5, 2, mode="interp") if len(a) >= 5 else a


def clean_track(rec: Recording, settings: CleanSettings = CleanSettings()) -> Track:
    """`clean_fixes` then `close_loop`: the whole cleaning without trimming.

    Raises:
        CourseError: fewer than 3 usable points, or no movement at all.
    """
    return close_loop(clean_fixes(rec, settings), settings)


def clean_fixes(rec: Recording, settings: CleanSettings = CleanSettings()) -> Track:
    """Usable fixes in ENU: no NaN, no standstill, no pause clusters, no GPS spikes.

    Raises:
        CourseError: fewer than 3 usable points, or no movement at all.
    """
    where = str(rec.path)
    lat, lon = np.asarray(rec.lat_deg, float), np.asarray(rec.lon_deg, float)
    ok = np.isfinite(lat) & np.isfinite(lon) & (np.abs(lat) <= 90) & (np.abs(lon) <= 180)
    # (0, 0) is what some devices write before the first fix.
    ok &= ~((lat == 0) & (lon == 0))
    repeated = _repeats(lat, lon, rec.time_s) & ok
    ok &= ~repeated
    if ok.sum() < 3:
        raise CourseError(f"{where}: only {int(ok.sum())} usable GPS points (need at least 3)")
    index = np.flatnonzero(ok)
    lat, lon = lat[ok], lon[ok]
    x, y, _ = pymap3d.geodetic2enu(lat, lon, np.zeros_like(lat), lat[0], lon[0], 0.0)
    x, y = np.asarray(x, float), np.asarray(y, float)
    t = None if rec.time_s is None else np.asarray(rec.time_s, float)[ok]
    moving_speed0 = 0
    if rec.speed_mps is not None:
        speed0 = np.nan_to_num(rec.speed_mps[ok], nan=np.inf) < settings.stopped_speed_mps
        moving = _gps_speed(x, y, t) >= settings.moving_gps_speed_mps
        moving_speed0 = int(np.sum(speed0 & moving))
        still = speed0 & ~moving
        if (~still).sum() < 3:
            raise CourseError(f"{where}: only {int((~still).sum())} moving GPS points "
                              "(need at least 3)")
        index, x, y = index[~still], x[~still], y[~still]
        t = None if t is None else t[~still]
    ele = np.asarray(rec.ele_m, float)[index]
    good = np.isfinite(ele)
    if not good.any():
        ele = np.zeros_like(ele)  # flat: `course_elevation` says the file had no altitude
    else:
        ele = np.interp(np.arange(len(ele)), np.flatnonzero(good), ele[good])
    # ENU anchored at the first kept fix (the standstill before it is gone).
    lat, lon = np.asarray(rec.lat_deg, float)[index], np.asarray(rec.lon_deg, float)[index]
    origin = GeoOrigin(float(lat[0]), float(lon[0]), float(ele[0]))
    x, y, _ = pymap3d.geodetic2enu(lat, lon, np.full_like(lat, origin.alt_m),
                                   origin.lat_deg, origin.lon_deg, origin.alt_m)
    x, y = np.asarray(x, float), np.asarray(y, float)

    keep = _decimate(x, y, settings.min_step_m)
    if keep.sum() < 3:
        raise CourseError(f"{where}: all GPS points are identical (or within "
                          f"{settings.min_step_m} m of each other): no track to fit")
    x, y, ele, good, index = x[keep], y[keep], ele[keep], good[keep], index[keep]
    t = None if t is None else t[keep]
    keep = _drop_spikes(x, y, t, settings)
    x, y, ele, good, index = x[keep], y[keep], ele[keep], good[keep], index[keep]
    if len(x) < 3:
        raise CourseError(f"{where}: fewer than 3 GPS points left after removing jumps")
    return Track(x, y, ele, origin, False, index, moving_speed0, int(repeated.sum()),
                 altitude_share=float(good.mean()), stamped=t is not None)


def _repeats(lat: np.ndarray, lon: np.ndarray, time_s: np.ndarray | None) -> np.ndarray:
    """Records with the time and position of an earlier one. Left in, a stretch written
    twice made the course turn round at its end and ride it again (a 5.6 m "hairpin" and
    1.4 km more on gpxpy's korita-zbevnica.gpx with 50 fixes repeated). Without a time
    nothing is a copy: a route may come back to a point it passed."""
    out = np.zeros(len(lat), bool)
    if time_s is None:
        return out
    t = np.asarray(time_s, float)
    stamped = np.flatnonzero(np.isfinite(t))
    _, first = np.unique(np.column_stack([t, lat, lon])[stamped], axis=0, return_index=True)
    out[stamped] = True
    out[stamped[first]] = False
    return out


def _gps_speed(x: np.ndarray, y: np.ndarray, t: np.ndarray | None) -> np.ndarray:
    """Speed implied by the displacement over +-2 fixes (m/s); +inf without stamps."""
    if t is None or len(x) < 5:
        return np.full(len(x), np.inf)
    i = np.arange(len(x))
    a, b = np.clip(i - 2, 0, len(x) - 1), np.clip(i + 2, 0, len(x) - 1)
    dt = t[b] - t[a]
    dist = np.hypot(x[b] - x[a], y[b] - y[a])
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(dt > 0, dist / np.where(dt > 0, dt, 1.0), 0.0)


def close_loop(track: Track, settings: CleanSettings = CleanSettings()) -> Track:
    """Detect a closed loop and cut a lap file's overrun past the start line.

    Raises:
        CourseError: fewer than 3 fixes.
    """
    if len(track) < 3:
        raise CourseError("fewer than 3 GPS points on the track")
    x, y = track.x_m, track.y_m
    step = np.hypot(np.diff(x), np.diff(y))
    length = float(step.sum())
    gap = float(np.hypot(x[-1] - x[0], y[-1] - y[0]))
    closed = gap <= settings.closed_loop_gap_m and length >= settings.closed_loop_min_length_m
    if length >= settings.closed_loop_min_length_m:
        # A lap file often runs a few fixes past the line. Cut at the last fix near the start
        # that is still before it (along the start direction), or the closing chord would
        # run backwards and make a U-turn at the seam.
        far = np.flatnonzero(np.hypot(x - x[0], y - y[0]) > settings.closed_loop_gap_m)
        ahead = (np.array([x[far[0]] - x[0], y[far[0]] - y[0]]) if len(far)
                 else np.array([1.0, 0.0]))
        ahead /= np.linalg.norm(ahead)
        # The last 90 m, and at least the last 10 fixes: a sparse record (smart recording,
        # a fix every 20-70 m) may have none within the gap in its last 90 m.
        tail = len(x) - 1 - np.flatnonzero(np.cumsum(step[::-1]) < 3 * settings.closed_loop_gap_m)
        tail = np.union1d(tail, np.arange(max(len(x) - 10, 0), len(x) - 1))[::-1]
        tail = np.concatenate([[len(x) - 1], tail])
        dist = np.hypot(x[tail] - x[0], y[tail] - y[0])
        before = (x[tail] - x[0]) * ahead[0] + (y[tail] - y[0]) * ahead[1] < 0
        # `tail` runs backwards from the last fix; in ride order, the first stretch of fixes
        # that reaches the start from before it is the arrival. What follows it (circling
        # at the finish, the ride home) is not course, and a cut there would close the lap
        # with a turn-around only a few metres wide.
        near = dist <= settings.closed_loop_gap_m
        # Sparse fixes may straddle the line: the last before it farther than the gap (up
        # to 3 gaps), the next past it within the gap. The one before is the arrival.
        straddle = np.zeros_like(near)
        straddle[1:] = (before[1:] & ~before[:-1] & near[:-1]
                        & (dist[1:] <= 3 * settings.closed_loop_gap_m))
        cand = np.flatnonzero((near & before) | straddle)[::-1]
        if len(cand) and _arrives_like_start(x, y, int(tail[cand[0]]), ahead, settings):
            run = cand[: int(np.argmax(np.diff(cand) != -1)) + 1] if np.any(
                np.diff(cand) != -1) else cand
            best = int(tail[run[np.argmin(dist[run])]])
            closed = True
            track = replace(track.take(slice(0, best + 1)),
                            loop_overrun_m=float(step[best:].sum()))
            x, y = track.x_m, track.y_m
        elif closed and not _arrives_like_start(x, y, len(x) - 1, ahead, settings):
            # Out along a road and back along it to the start (a ride from home): joining
            # the ends would be a U-turn at the seam, so this is a point-to-point course.
            closed = False
    if closed:
        # The end fix that coincides with the start would be a zero-length step across the seam.
        while len(track) > 3 and np.hypot(track.x_m[-1] - track.x_m[0],
                                          track.y_m[-1] - track.y_m[0]) < settings.min_step_m:
            track = track.take(slice(0, -1))
    return replace(track, closed_loop=closed)


def _arrives_like_start(x: np.ndarray, y: np.ndarray, end: int, ahead: np.ndarray,
                        settings: CleanSettings) -> bool:
    """True if the track arrives at fix `end` heading within 90 deg of the start direction.

    The arrival direction is the chord from the last fix `closed_loop_gap_m` or more
    before `end` (so GPS jitter at the line does not decide it).
    """
    far = np.flatnonzero(np.hypot(x[:end] - x[end], y[:end] - y[end])
                         > settings.closed_loop_gap_m)
    if not len(far):
        return True
    arrive = np.array([x[end] - x[far[-1]], y[end] - y[far[-1]]])
    return float(arrive @ ahead) > 0.0


def _decimate(x: np.ndarray, y: np.ndarray, min_step_m: float) -> np.ndarray:
    """Keep a fix only if it is at least `min_step_m` from the last kept one.

    Removes duplicates and the wander of a paused GPS without touching moving fixes
    (1 Hz at racing speed is 5-20 m apart).
    """
    keep = np.zeros(len(x), dtype=bool)
    keep[0] = True
    last = 0
    # Fast path: a vectorised test finds the points that are trivially far enough; the loop
    # only needs to look at the rest (pauses), which keeps 100 km tracks in milliseconds.
    step = np.hypot(np.diff(x), np.diff(y))
    if np.all(step >= min_step_m):
        keep[:] = True
        return keep
    x2, y2 = x.tolist(), y.tolist()
    lim = min_step_m * min_step_m
    for i in range(1, len(x)):
        dx, dy = x2[i] - x2[last], y2[i] - y2[last]
        if dx * dx + dy * dy >= lim:
            keep[i] = True
            last = i
    return keep


def _drop_spikes(x: np.ndarray, y: np.ndarray, t: np.ndarray | None,
                 settings: CleanSettings) -> np.ndarray:
    """Remove fixes that jump away and come back (GPS multipath), keep real gaps.

    A step is a jump if its implied speed exceeds `max_speed_mps` (with stamps) or if it
    is ten times the typical step and over 100 m (without). If a fix within the next
    `spike_window` fixes is plausibly reachable from the fix before the jump, everything
    in between is a spike; otherwise the jump is a real gap (pause, tunnel) and is kept.
    Without stamps that fix must also have come back (half as far from the fix before
    the jump as the jump went), within `unstamped_spike_window` fixes: a route drawn on a
    map has points every few metres in bends and one after a 500 m straight, and the
    straight's far end is no spike, nor the rest of a lap that comes back to its start.
    """
    n = len(x)
    window = settings.spike_window if t is not None else settings.unstamped_spike_window
    keep = np.ones(n, dtype=bool)
    step = np.hypot(np.diff(x), np.diff(y))
    typical = float(np.median(step)) if len(step) else 0.0

    def plausible(a: int, b: int) -> bool:
        dist = float(np.hypot(x[b] - x[a], y[b] - y[a]))
        if t is not None and np.isfinite(t[a]) and np.isfinite(t[b]):
            return bool(dist <= settings.max_speed_mps * max(t[b] - t[a], 1.0) + 10.0)
        return dist <= max(10.0 * typical * (b - a), 100.0)

    last = 0
    i = 1
    while i < n:
        if plausible(last, i):
            last = i
            i += 1
            continue
        went = float(np.hypot(x[i] - x[last], y[i] - y[last]))
        back = next((j for j in range(i + 1, min(i + 1 + window, n))
                     if plausible(last, j) and (
                         t is not None or np.hypot(x[j] - x[last], y[j] - y[last]) < went / 2)),
                    None)
        if back is None:  # a real gap: accept the new position
            last = i
            i += 1
        else:
            keep[i:back] = False
            last = back
            i = back + 1
    return keep
