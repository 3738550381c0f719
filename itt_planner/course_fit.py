"""GPS recording -> smooth `Course` (model.md section 1).

Raw GPS has 3-5 m of noise, so curvature taken from the points directly is useless. The
pipeline here:

1. clean: drop fixes without a position, out-of-range coordinates, pause points (fixes
   closer than `min_step_m` to the last kept one, or with a device speed near zero) and
   GPS spikes (a fix, or a short run of fixes, that jumps away and comes back);
2. project to ENU anchored at the first fix (pymap3d);
3. detect a closed loop (end within `closed_loop_gap_m` of the start on a long track) and
   treat it periodically: the data is wrapped around the seam before smoothing, so the
   centre line has no kink or gap where the lap closes;
4. fit x(u), y(u) with cubic smoothing splines (`scipy.interpolate.make_smoothing_spline`,
   three O(n) passes): two with a moderate smoothing length that locate the corners and
   re-parametrise each fix by its foot point on the curve, then one whose smoothing length
   adapts to the road (30 m on straights, where it keeps the noise out of the curvature,
   0.42 x the local radius but at least 10 m in corners). Only stretches whose heading
   turns by more than ~30 deg within +-30 m count as corners: the second pass bends by a
   few degrees on a noisy straight, and without that gate each bump got a short smoothing
   length and survived as a spurious 150-300 m "corner". All lengths scale with the noise
   measured after the first pass;
5. resample at uniform arc length of the fitted curve, heading from the spline derivative,
   then a Gaussian filter on the heading (spreads the curvature bursts that the last few
   fixes of noise leave in a corner) and positions re-integrated from it;
6. fit altitude z(s) with a much longer smoothing length (barometric and GPS altitude
   jitter by metres, which would make metre-scale grades absurd).

A cubic smoothing spline with weights w_i and penalty lam has a local equivalent-kernel
bandwidth h = (lam / (w * rho)) ** 0.25, rho = points per metre (Silverman 1984); the
weights below are set from that relation to get a chosen smoothing length in metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pymap3d
from scipy.interpolate import BSpline, make_smoothing_spline
from scipy.ndimage import gaussian_filter1d, maximum_filter1d, uniform_filter1d

from itt_planner.course import Course, GeoOrigin
from itt_planner.errors import CourseError
from itt_planner.track_files import Recording, read_recording


@dataclass(frozen=True)
class FitSettings:
    """Knobs of the GPS -> course fit. Defaults are tuned for 1 Hz bike GPS (3-5 m noise).

    Attributes:
        ds_m: grid step of the resulting course.
        min_step_m: a fix closer than this to the last kept fix is a pause point.
        stopped_speed_mps: fixes whose device speed is below this are dropped (GPS wanders
            while the rider stands still).
        max_speed_mps: implied speeds above this mark a GPS jump (no bike does 30 m/s on
            a course that matters here; Zwift descents top out below it).
        spike_window: a jump that comes back within this many fixes is a spike and is
            removed; one that does not is a real gap and is kept.
        straight_scale_m: smoothing length on straights.
        min_scale_m: shortest smoothing length, in the tightest corners.
        radius_scale: smoothing length as a fraction of the local radius in corners.
        corner_search_scale_m: smoothing length of the first passes that locate corners.
        corner_turn_rad: a stretch is a corner (and gets a shorter smoothing length) only
            if the heading of the first-pass curve changes by more than this across
            +-`straight_scale_m`; noise on a straight does not.
        nominal_noise_m: GPS noise the smoothing lengths are tuned for; they scale with the
            noise measured on the track, but by no less than `min_noise_factor` (device
            tracks are pre-filtered and look cleaner than they are).
        heading_sigma_m: width of the Gaussian filter on the heading.
        drift_scale_m: smoothing length of the position correction after that filter.
        altitude_scale_m: smoothing length of the altitude profile.
        max_grade: steeper stretches of the fitted profile are smoothed harder.
        closed_loop_gap_m: a track that ends this close to its start is a closed loop...
        closed_loop_min_length_m: ... if it is at least this long.
    """

    ds_m: float = 1.0
    min_step_m: float = 2.0
    stopped_speed_mps: float = 0.5
    max_speed_mps: float = 30.0
    spike_window: int = 30
    straight_scale_m: float = 30.0
    min_scale_m: float = 10.0
    radius_scale: float = 0.42
    corner_search_scale_m: float = 15.0
    corner_turn_rad: float = 0.5
    nominal_noise_m: float = 3.0
    min_noise_factor: float = 0.75
    heading_sigma_m: float = 9.0
    drift_scale_m: float = 100.0
    altitude_scale_m: float = 60.0
    max_grade: float = 0.25
    closed_loop_gap_m: float = 30.0
    closed_loop_min_length_m: float = 1000.0


@dataclass(frozen=True)
class Track:
    """Cleaned ENU fixes (m) with the geodetic origin and the closed-loop flag."""

    x_m: np.ndarray
    y_m: np.ndarray
    z_m: np.ndarray
    origin: GeoOrigin
    closed_loop: bool


def fit_course_file(path: str | Path, settings: FitSettings = FitSettings()) -> Course:
    """Read a GPX/TCX/FIT/CSV file and fit a course to it.

    Raises:
        CourseError: unreadable file, or not enough usable points (names the file).
    """
    return fit_course(read_recording(path), settings)


def fit_course(rec: Recording, settings: FitSettings = FitSettings()) -> Course:
    """Fit a smooth course to a GPS recording.

    Raises:
        CourseError: too few usable points, or all points identical (names the file).
    """
    track = clean_track(rec, settings)
    s, x, y, theta, kappa, s_pts = _fit_plan(track, settings)
    z = _fit_altitude(s_pts, track.z_m, float(s[-1]), track.closed_loop, settings)
    return Course.from_centerline(
        rec.path.name.split(".")[0], x, y, z(s), origin=track.origin,
        closed_loop=track.closed_loop, ds_m=settings.ds_m, theta_rad=theta, kappa_per_m=kappa,
        source=str(rec.path), source_sha256=rec.sha256,
    )


# ---- cleaning ---------------------------------------------------------------------------
def clean_track(rec: Recording, settings: FitSettings = FitSettings()) -> Track:
    """Usable fixes in ENU: no NaN, no pause clusters, no GPS spikes.

    Raises:
        CourseError: fewer than 3 usable points, or no movement at all.
    """
    where = str(rec.path)
    lat, lon = np.asarray(rec.lat_deg, float), np.asarray(rec.lon_deg, float)
    ok = np.isfinite(lat) & np.isfinite(lon) & (np.abs(lat) <= 90) & (np.abs(lon) <= 180)
    # (0, 0) is what some devices write before the first fix.
    ok &= ~((lat == 0) & (lon == 0))
    if rec.speed_mps is not None:
        ok &= ~(np.nan_to_num(rec.speed_mps, nan=np.inf) < settings.stopped_speed_mps)
    if ok.sum() < 3:
        raise CourseError(f"{where}: only {int(ok.sum())} usable GPS points (need at least 3)")
    ele = np.asarray(rec.ele_m, float)[ok]
    if np.all(np.isnan(ele)):
        ele = np.zeros_like(ele)  # a flat course is the honest reading of "no altitude"
    else:
        good = np.isfinite(ele)
        ele = np.interp(np.arange(len(ele)), np.flatnonzero(good), ele[good])
    lat, lon = lat[ok], lon[ok]
    origin = GeoOrigin(float(lat[0]), float(lon[0]), float(ele[0]))
    x, y, _ = pymap3d.geodetic2enu(lat, lon, np.full_like(lat, origin.alt_m),
                                   origin.lat_deg, origin.lon_deg, origin.alt_m)
    x, y = np.asarray(x, float), np.asarray(y, float)
    t = None if rec.time_s is None else np.asarray(rec.time_s, float)[ok]

    keep = _decimate(x, y, settings.min_step_m)
    if keep.sum() < 3:
        raise CourseError(f"{where}: all GPS points are identical (or within "
                          f"{settings.min_step_m} m of each other): no track to fit")
    x, y, ele = x[keep], y[keep], ele[keep]
    t = None if t is None else t[keep]
    keep = _drop_spikes(x, y, t, settings)
    x, y, ele = x[keep], y[keep], ele[keep]
    if len(x) < 3:
        raise CourseError(f"{where}: fewer than 3 GPS points left after removing jumps")

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
        tail = len(x) - 1 - np.flatnonzero(np.cumsum(step[::-1]) < 3 * settings.closed_loop_gap_m)
        tail = np.concatenate([[len(x) - 1], tail])
        dist = np.hypot(x[tail] - x[0], y[tail] - y[0])
        before = (x[tail] - x[0]) * ahead[0] + (y[tail] - y[0]) * ahead[1] < 0
        # `tail` runs backwards from the last fix; in ride order, the first stretch of fixes
        # that reaches the start from before it is the arrival. What follows it (circling
        # at the finish, the ride home) is not course, and a cut there would close the lap
        # with a turn-around only a few metres wide.
        cand = np.flatnonzero((dist <= settings.closed_loop_gap_m) & before)[::-1]
        if len(cand) and _arrives_like_start(x, y, int(tail[cand[0]]), ahead, settings):
            run = cand[: int(np.argmax(np.diff(cand) != -1)) + 1] if np.any(
                np.diff(cand) != -1) else cand
            best = int(tail[run[np.argmin(dist[run])]])
            closed = True
            x, y, ele = x[: best + 1], y[: best + 1], ele[: best + 1]
        elif closed and not _arrives_like_start(x, y, len(x) - 1, ahead, settings):
            # Out along a road and back along it to the start (a ride from home): joining
            # the ends would be a U-turn at the seam, so this is a point-to-point course.
            closed = False
    if closed:
        # The end fix that coincides with the start would be a zero-length step across the seam.
        while len(x) > 3 and np.hypot(x[-1] - x[0], y[-1] - y[0]) < settings.min_step_m:
            x, y, ele = x[:-1], y[:-1], ele[:-1]
    return Track(x, y, ele, origin, closed)


def _arrives_like_start(x: np.ndarray, y: np.ndarray, end: int, ahead: np.ndarray,
                        settings: FitSettings) -> bool:
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
                 settings: FitSettings) -> np.ndarray:
    """Remove fixes that jump away and come back (GPS multipath), keep real gaps.

    A step is a jump if its implied speed exceeds `max_speed_mps` (with stamps) or if it
    is ten times the typical step and over 100 m (without). If a fix within the next
    `spike_window` fixes is plausibly reachable from the fix before the jump, everything
    in between is a spike; otherwise the jump is a real gap (pause, tunnel) and is kept.
    """
    n = len(x)
    keep = np.ones(n, dtype=bool)
    step = np.hypot(np.diff(x), np.diff(y))
    typical = float(np.median(step)) if len(step) else 0.0

    def plausible(a: int, b: int) -> bool:
        dist = float(np.hypot(x[b] - x[a], y[b] - y[a]))
        if t is not None and np.isfinite(t[a]) and np.isfinite(t[b]):
            return dist <= settings.max_speed_mps * max(t[b] - t[a], 1.0) + 10.0
        return dist <= max(10.0 * typical * (b - a), 100.0)

    last = 0
    i = 1
    while i < n:
        if plausible(last, i):
            last = i
            i += 1
            continue
        back = next((j for j in range(i + 1, min(i + 1 + settings.spike_window, n))
                     if plausible(last, j)), None)
        if back is None:  # a real gap: accept the new position
            last = i
            i += 1
        else:
            keep[i:back] = False
            last = back
            i = back + 1
    return keep


# ---- plan view fit -----------------------------------------------------------------------
def _fit_plan(track: Track, st: FitSettings
              ) -> tuple[np.ndarray, ...]:
    """Adaptive smoothing splines through the fixes.

    Returns arc length, x, y, heading, curvature on a uniform arc-length grid (closed loops end on
    their start point), and the arc length of each input fix on that grid.
    """
    x, y = track.x_m, track.y_m
    xy = np.column_stack([x, y])
    if track.closed_loop:
        xy_c = np.vstack([xy, xy[:1]])
    else:
        xy_c = xy
    u = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy_c, axis=0).T))])
    period = float(u[-1])
    n_pts = len(xy)
    u_pts = u[:n_pts]
    off = 0
    if track.closed_loop:
        # Wrap enough data around the seam that the fit there sees the road on both sides.
        pad_m = min(4.0 * st.straight_scale_m + 50.0, 0.45 * period)
        head = u_pts < pad_m
        tail = u_pts > period - pad_m
        off = int(tail.sum())
        u_fit = np.concatenate([u_pts[tail] - period, u_pts, u_pts[head] + period])
        xy_fit = np.vstack([xy[tail], xy, xy[head]])
    else:
        u_fit, xy_fit = u_pts, xy
    if len(u_fit) < 5:
        # make_smoothing_spline needs 5 points; densify a tiny track linearly.
        u_new = np.linspace(u_fit[0], u_fit[-1], 5)
        xy_fit = np.column_stack([np.interp(u_new, u_fit, xy_fit[:, k]) for k in range(2)])
        u_fit = u_new

    # Passes 1 and 2 use one moderate smoothing length everywhere: enough to find where the
    # corners are and to re-parametrise the fixes by their foot point on the curve (the
    # chord length of noisy fixes carries along-track noise that would distort corners).
    # Pass 3 uses the adaptive smoothing length set from pass 2's radius. All lengths
    # scale with the noise measured after pass 1 (a map-drawn track needs far less).
    h = np.full(len(u_fit), st.corner_search_scale_m)
    spl = _smooth(u_fit, xy_fit, h)
    noise = _noise_factor(spl, u_fit, xy_fit, st)
    for k in range(1, 3):
        u_fit = _reparametrise(spl, u_fit, xy_fit)
        if k == 2:
            kap = np.abs(_curvature(spl, u_fit))
            # Noise bends a straight a few degrees back and forth, a corner turns one way.
            # Only where the heading changes by `corner_turn_rad` across +-straight_scale_m
            # does the local radius shorten the smoothing length; otherwise a noise bump on
            # a straight shortens it and survives into the final curvature.
            d1 = spl.derivative(1)(u_fit)
            th = np.unwrap(np.arctan2(d1[:, 1], d1[:, 0]))
            reach = st.straight_scale_m * noise
            turn = np.abs(np.interp(u_fit + reach, u_fit, th)
                          - np.interp(u_fit - reach, u_fit, th))
            kap = np.where(turn > st.corner_turn_rad, kap, 0.0)
            win = max(3, int(st.straight_scale_m / max(np.median(np.diff(u_fit)), 1e-3)) | 1)
            kap = maximum_filter1d(kap, win, mode="nearest")
            h = np.clip(st.radius_scale / np.maximum(kap, 1e-9), st.min_scale_m,
                        st.straight_scale_m)
            h = uniform_filter1d(h, win, mode="nearest")
        spl = _smooth(u_fit, xy_fit, h * noise)
    if track.closed_loop:
        u_pts = u_fit[off: off + n_pts]
        period = float(u_fit[off + n_pts] - u_fit[off])
    else:
        u_pts = u_fit if len(u_fit) == n_pts else np.interp(
            np.arange(n_pts), np.linspace(0, n_pts - 1, len(u_fit)), u_fit)

    # Arc length of the fitted curve, then a uniform grid in it.
    u0 = float(u_pts[0])
    u1 = u0 + period if track.closed_loop else float(u_fit[-1])
    n_dense = max(int((u1 - u0) / 0.25), 10)
    ud = np.linspace(u0, u1, n_dense + 1)
    d1 = spl.derivative(1)(ud)
    speed = np.hypot(d1[:, 0], d1[:, 1])
    s_dense = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(ud))])
    length = float(s_dense[-1])
    n = int(np.floor(length / st.ds_m))
    s_grid = np.linspace(0.0, n * st.ds_m, n + 1)
    if track.closed_loop and length - s_grid[-1] > 1e-6:
        s_grid = np.append(s_grid, length)  # end exactly on the start point
    ug = np.interp(s_grid, s_dense, ud)
    pos = spl(ug)
    d1 = spl.derivative(1)(ug)
    theta = np.unwrap(np.arctan2(d1[:, 1], d1[:, 0]))
    s_pts = np.interp(u_pts, ud, s_dense)
    x, y, theta, kappa = _smooth_heading(s_grid, pos[:, 0], pos[:, 1], theta,
                                         track.closed_loop, st.heading_sigma_m * noise, st)
    return s_grid, x, y, theta, kappa, s_pts


def _smooth_heading(s: np.ndarray, x: np.ndarray, y: np.ndarray, theta: np.ndarray,
                    closed: bool, sigma_m: float, st: FitSettings
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Low-pass the heading, then rebuild a centre line that follows it.

    The position spline leaves a few fixes' worth of noise in where a corner turns: the
    total turn is right but it comes in bursts (curvature spikes a rider could never
    follow). A Gaussian filter on theta(s) (a positive kernel: it never sharpens) spreads
    each burst over the corner. Integrating the filtered heading drifts by decimetres per
    kilometre, so the long-wave difference to the spline positions is added back; that
    correction bends the line by far less than 1/1000 m^-1.
    """
    ds = float(s[1] - s[0])
    mode = "wrap" if closed else "nearest"
    if closed:
        # theta gains a whole turn per lap; filter the periodic remainder.
        trend = (theta[-1] - theta[0]) * (s - s[0]) / (s[-1] - s[0])
        th = gaussian_filter1d((theta - trend)[:-1], sigma_m / ds, mode="wrap")
        th = np.append(th, th[0]) + trend
    else:
        th = gaussian_filter1d(theta, sigma_m / ds, mode="nearest")
    step = np.diff(s)
    mid = 0.5 * (th[1:] + th[:-1])
    xi = x[0] + np.concatenate([[0.0], np.cumsum(step * np.cos(mid))])
    yi = y[0] + np.concatenate([[0.0], np.cumsum(step * np.sin(mid))])
    if closed:
        # Spread the closure error of the integration over the lap so the difference to the
        # spline is periodic (the wrap-around filter below then joins the seam exactly).
        frac = (s - s[0]) / (s[-1] - s[0])
        xi = xi - (xi[-1] - x[-1]) * frac
        yi = yi - (yi[-1] - y[-1]) * frac
    corr = st.drift_scale_m / ds
    xo = xi + gaussian_filter1d(x - xi, corr, mode=mode)
    yo = yi + gaussian_filter1d(y - yi, corr, mode=mode)
    return xo, yo, th, np.gradient(th, s)


def _smooth(u: np.ndarray, values: np.ndarray, scale_m: np.ndarray) -> BSpline:
    """Cubic smoothing spline with a local smoothing length `scale_m` (m) per point.

    Weights follow from the equivalent-kernel bandwidth h = (lam / (w * rho)) ** 0.25.
    """
    du = np.gradient(u)
    rho = 1.0 / np.maximum(uniform_filter1d(du, 5, mode="nearest"), 1e-3)
    lam = float(np.max(scale_m)) ** 4
    return make_smoothing_spline(u, values, w=lam / (rho * scale_m**4), lam=lam)


def _noise_factor(spl: BSpline, u: np.ndarray, xy: np.ndarray, st: FitSettings) -> float:
    """Scale of all smoothing lengths: (measured GPS noise / nominal noise) ** 0.4.

    The noise is the robust spread (MAD) of the fixes' offsets from the first-pass curve;
    0.4 is the exponent of the optimal bandwidth of a cubic smoothing spline.
    """
    resid = np.hypot(*(xy - spl(u)).T)
    sigma = 1.4826 * float(np.median(resid)) / 1.1774  # median of a 2-D Rayleigh -> sigma
    return float(np.clip((max(sigma, 1e-3) / st.nominal_noise_m) ** 0.4, st.min_noise_factor, 1.5))


def _reparametrise(spl: BSpline, u: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """New parameter of each fix: its foot point on the fitted curve (kept increasing)."""
    step = 0.5
    ud = np.arange(u[0], u[-1] + step, step)
    cd = spl(ud)
    half = 80  # search +-40 m around the current parameter
    idx = np.clip(np.round((u - u[0]) / step).astype(int), 0, len(ud) - 1)
    offs = np.arange(-half, half + 1)
    cand = np.clip(idx[:, None] + offs[None, :], 0, len(ud) - 1)
    d2 = ((cd[cand] - xy[:, None, :]) ** 2).sum(axis=2)
    new = ud[cand[np.arange(len(u)), np.argmin(d2, axis=1)]]
    # Fixes must stay in order; a tiny floor keeps the spline abscissae strictly increasing.
    gap = np.maximum(np.diff(new), 1e-2)
    return np.concatenate([[new[0]], new[0] + np.cumsum(gap)])


def _curvature(spl: BSpline, u: np.ndarray) -> np.ndarray:
    """Signed curvature of a parametric spline (positive = turning left)."""
    d1 = spl.derivative(1)(u)
    d2 = spl.derivative(2)(u)
    num = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    return num / np.maximum(np.hypot(d1[:, 0], d1[:, 1]), 1e-9) ** 3


# ---- altitude ------------------------------------------------------------------------------
def _fit_altitude(s_pts: np.ndarray, z_pts: np.ndarray, length_m: float, closed: bool,
                  st: FitSettings) -> BSpline:
    """Smoothing spline z(s) with a long smoothing length (altitude jitters by metres).

    Closed loops are wrapped like the plan view so the profile joins at the seam.
    """
    order = np.argsort(s_pts, kind="stable")
    s, z = s_pts[order], z_pts[order]
    uniq = np.concatenate([[True], np.diff(s) > 1e-3])
    s, z = s[uniq], z[uniq]
    if closed:
        pad = min(4.0 * st.altitude_scale_m, 0.45 * length_m)
        head, tail = s < pad, s > length_m - pad
        s = np.concatenate([s[tail] - length_m, s, s[head] + length_m])
        z = np.concatenate([z[tail], z, z[head]])
    if len(s) < 5:
        s_new = np.linspace(s[0], s[-1], 5)
        z = np.interp(s_new, s, z)
        s = s_new
    # Roads steeper than `max_grade` do not exist on a course worth planning; where the
    # fit says so, the altitude data is wrong there (baro jump after a pause, GPS altitude
    # after a gap), so smooth those stretches harder until the grade is plausible.
    scale = np.full(len(s), st.altitude_scale_m)
    for _ in range(8):
        spl = _smooth(s, z, scale)
        grid = np.arange(s[0], s[-1], 1.0)
        steep_grid = np.abs(spl.derivative(1)(grid)) > 0.95 * st.max_grade
        if not steep_grid.any():
            break
        # Data points within 50 m of a steep stretch get the longer smoothing length.
        steep = np.interp(s, grid, maximum_filter1d(steep_grid.astype(float), 101)) > 0
        widen = steep
        scale = np.where(widen, scale * 2.0, scale)
    return spl
