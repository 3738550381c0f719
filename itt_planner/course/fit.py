"""GPS recording -> smooth `Course` (model.md section 1).

Raw GPS has 3-5 m of noise, so curvature taken from the points directly is useless. The
pipeline here:

1. clean (`track_clean`): drop fixes without a position, standstill (device speed near
   zero while the GPS does not move either), pause clusters and GPS spikes; ENU at the
   first moving fix (pymap3d);
2. trim to the race (`course_trim`): `--start`/`--finish` overrides, a route, or the
   post-finish U-turn heuristic;
3. detect a closed loop (`track_clean.close_loop`) and treat it periodically: the data
   is wrapped around the seam before smoothing, so the centre line has no kink or gap
   where the lap closes;
4. fit x(u), y(u) with cubic smoothing splines (`scipy.interpolate.make_smoothing_spline`,
   three O(n) passes): two with a moderate smoothing length that locate the corners and
   re-parametrise each fix by its foot point on the curve, then one whose smoothing length
   adapts to the road (30 m on straights, where it keeps the noise out of the curvature,
   0.42 x the local radius but at least 10 m in corners). Only stretches whose heading
   turns by more than ~30 deg within +-30 m count as corners: the second pass bends by a
   few degrees on a noisy straight, and without that gate each bump got a short smoothing
   length and survived as a spurious 150-300 m "corner". All lengths scale with the noise
   measured after the first pass. A gap in the fixes (`track_gaps`) is filled with points
   on its chord first: the spline would swing wide of it;
5. resample at uniform arc length of the fitted curve, heading from the spline derivative,
   then a Gaussian filter on the heading (spreads the curvature bursts that the last few
   fixes of noise leave in a corner) and positions re-integrated from it;
6. fit altitude z(s) with a much longer smoothing length (barometric and GPS altitude
   jitter by metres, which would make metre-scale grades absurd), from the source chosen
   in `course_elevation` (device, smoothed, route or a mix), with its checks;
7. road width: `GPS_ROAD_WIDTH_M` unless set for the course or per stretch.

What trimming, the gaps, the elevation choice and the width did is kept in `Course.build`.

The smoothing splines, and the altitude's fit with them, are in `course.smoothing`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Literal, cast

import numpy as np
from scipy.interpolate import BSpline
from scipy.ndimage import gaussian_filter1d, maximum_filter1d, uniform_filter1d

from itt_planner.course.elevation import ElevationOptions, build_profile
from itt_planner.course.geometry import GPS_ROAD_WIDTH_M, Course
from itt_planner.course.smoothing import fit_altitude, smoothing_spline
from itt_planner.course.track_clean import CleanSettings, Track, clean_fixes, close_loop
from itt_planner.course.track_files import Recording, read_recording
from itt_planner.course.track_gaps import fill_gaps, gap_report
from itt_planner.course.trim import TrimOptions, trim_track
from itt_planner.errors import CourseError


@dataclass(frozen=True)
class FitSettings:
    """Knobs of the GPS -> course fit. Defaults are tuned for 1 Hz bike GPS (3-5 m noise).

    Attributes:
        ds_m: grid step of the resulting course.
        clean: the cleaning of the fixes (`track_clean`).
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
    """

    ds_m: float = 1.0
    clean: CleanSettings = CleanSettings()
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


@dataclass(frozen=True)
class WidthStretch:
    """The full road width (m) from `from_m` to `to_m` along the course."""

    from_m: float
    to_m: float
    width_m: float


@dataclass(frozen=True)
class CourseOptions:
    """What a GPS course is made of, beyond the track: the race's extent, the altitude
    source, the road width (`road_width_m`, overridden per stretch by `widths`), the laps."""

    trim: TrimOptions = TrimOptions()
    elevation: ElevationOptions = ElevationOptions()
    road_width_m: float = GPS_ROAD_WIDTH_M
    widths: tuple[WidthStretch, ...] = ()
    laps: int = 1


def fit_course_file(path: str | Path, settings: FitSettings = FitSettings(),
                    options: CourseOptions = CourseOptions()) -> Course:
    """Read a GPX/TCX/FIT/CSV file and fit a course to it.

    Raises:
        CourseError: unreadable file, or not enough usable points (names the file).
    """
    return fit_course(read_recording(path), settings, options)


def fit_course(rec: Recording, settings: FitSettings = FitSettings(),
               options: CourseOptions = CourseOptions()) -> Course:
    """Fit a smooth course to a GPS recording (trimmed, altitude checked, widths set).

    Raises:
        CourseError: too few usable points, all points identical, an invalid trim, width
            or elevation choice (names the file).
    """
    track = clean_fixes(rec, settings.clean)
    track, trim = trim_track(track, rec, options.trim)
    track = close_loop(track, settings.clean)
    s, x, y, theta, kappa, s_pts = _fit_plan(track, settings)

    def fit(sp: np.ndarray, zp: np.ndarray, scale_m: float) -> np.ndarray:
        return fit_altitude(sp, zp, float(s[-1]), track.closed_loop, scale_m,
                            settings.max_grade)(s)

    try:
        z, elevation = build_profile(s, x, y, track.origin, (s_pts, track.z_m),
                                     options.trim.route, options.elevation, fit,
                                     settings.altitude_scale_m, track.altitude_share)
        width, width_report = _road_width(s, options)
    except CourseError as err:
        raise CourseError(f"{rec.path}: {err}") from None
    trim_report = trim.as_dict()
    trim_report["finish_m"] = round(trim.start_m + float(track.distance_m[-1]), 1)
    trim_report["moving_with_speed_0"] = track.moving_speed0
    trim_report["repeated"] = track.repeated
    trim_report["notes"].extend(track.notes())
    # Where the fixes are along the course's own arc length (its heading was filtered).
    s_fix = np.interp(s_pts, s, np.append(0.0, np.cumsum(np.hypot(np.diff(x), np.diff(y)))))
    gap_rows, gap_warnings = gap_report(np.column_stack([track.x_m, track.y_m]), None if rec.time_s
                                        is None else np.asarray(rec.time_s, float)[track.index],
                                        s_fix, track.stamped)
    # A run's or a walk's track is still a route; what was done on it was no ride.
    sport = [f"the file is a {rec.sport!r} activity, not a ride: its track is read as a course"
             ] if rec.other_sport else []
    build = {"trim": trim_report, "elevation": elevation, "road_width": width_report, "gaps":
             gap_rows, "sport": rec.sport, "air_temperature_c": _json_float(
                 rec.air_temperature_c(track.index)),
             "warnings": trim.warnings() + list(elevation["warnings"]) + gap_warnings + sport}
    return Course.from_centerline(
        rec.path.name.split(".")[0], x, y, z, origin=track.origin,
        closed_loop=track.closed_loop, ds_m=settings.ds_m, theta_rad=theta, kappa_per_m=kappa,
        width_left_m=width / 2, width_right_m=width / 2,
        source=str(rec.path), source_sha256=rec.sha256, build=build,
    ).laps(options.laps)


def _json_float(value: float) -> float | None:
    """`value`, or None for NaN (a course's build is JSON)."""
    return value if math.isfinite(value) else None


def _road_width(s: np.ndarray, options: CourseOptions) -> tuple[np.ndarray, dict[str, Any]]:
    """Full road width at each grid point, and how it was set.

    Raises:
        CourseError: a width that is not positive, or a stretch outside the course.
    """
    width = np.full(len(s), float(options.road_width_m))
    if not options.road_width_m > 0:
        raise CourseError(f"road width {options.road_width_m} m: must be positive")
    for w in options.widths:
        if not (w.width_m > 0 and 0 <= w.from_m < w.to_m):
            raise CourseError(f"road width stretch {w}: need 0 <= from_m < to_m, width_m > 0")
        if w.from_m > s[-1]:
            raise CourseError(f"road width stretch {w}: starts after the course ends "
                              f"({s[-1]:.0f} m)")
        width[(s >= w.from_m) & (s <= w.to_m)] = w.width_m
    report = {"default_m": float(options.road_width_m),
              "default_is": ("GPS_ROAD_WIDTH_M (closed-road time trial, see course.py)"
                             if options.road_width_m == GPS_ROAD_WIDTH_M else "set"),
              "stretches": [asdict(w) for w in options.widths],
              "min_m": float(width.min()), "max_m": float(width.max())}
    return width, report


# ---- plan view fit -----------------------------------------------------------------------
def _fit_plan(track: Track, st: FitSettings  # noqa: PLR0915  (one pipeline; passes share state)
              ) -> tuple[np.ndarray, ...]:
    """Adaptive smoothing splines through the fixes.

    Returns arc length, x, y, heading, curvature on a uniform arc-length grid (closed loops end on
    their start point), and the arc length of each input fix on that grid.
    """
    x, y = track.x_m, track.y_m
    xy = np.column_stack([x, y])
    xy_c = np.vstack([xy, xy[:1]]) if track.closed_loop else xy
    u = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy_c, axis=0).T))])
    period = float(u[-1])
    n_pts = len(xy)
    u_pts = u[:n_pts]
    off = 0
    if track.closed_loop:
        # Wrap enough data around the seam that the fit there sees the road on both sides
        # (5 fixes at least: a route's straight has its two ends only; 9 m off with none).
        pad_m, i = min(4.0 * st.straight_scale_m + 50.0, 0.45 * period), np.arange(n_pts)
        head, tail = (u_pts < pad_m) | (i < 5), (u_pts > period - pad_m) | (i >= n_pts - 5)
        off = int(tail.sum())
        u_fit = np.concatenate([u_pts[tail] - period, u_pts, u_pts[head] + period])
        xy_fit = np.vstack([xy[tail], xy, xy[head]])
    else:
        u_fit, xy_fit = u_pts, xy
    # Straight across the gaps; `at`: where each fix (padding included) went.
    u_fit, xy_fit, at = fill_gaps(u_fit, xy_fit)

    # Passes 1 and 2 use one moderate smoothing length everywhere: enough to find where the
    # corners are and to re-parametrise the fixes by their foot point on the curve (the
    # chord length of noisy fixes carries along-track noise that would distort corners).
    # Pass 3 uses the adaptive smoothing length set from pass 2's radius. All lengths
    # scale with the noise measured after pass 1 (a map-drawn track needs far less).
    h = np.full(len(u_fit), st.corner_search_scale_m)
    spl = smoothing_spline(u_fit, xy_fit, h)
    noise = _noise_factor(spl, u_fit[at], xy_fit[at], st)  # the fixes' noise, not the fill's
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
        spl = smoothing_spline(u_fit, xy_fit, h * noise)
    u_pts = u_fit[at[off: off + n_pts]]
    if track.closed_loop:
        period = float(u_fit[at[off + n_pts]] - u_pts[0])

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
    mode: Literal["wrap", "nearest"] = "wrap" if closed else "nearest"
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
    return cast(np.ndarray, num / np.maximum(np.hypot(d1[:, 0], d1[:, 1]), 1e-9) ** 3)
