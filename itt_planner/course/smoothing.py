"""Smoothing splines of a course fit (`course.fit`): the cubic smoothing spline with a
smoothing length in metres per point, and the altitude profile z(s) fitted with it.

A cubic smoothing spline with weights w_i and penalty lam has a local equivalent-kernel
bandwidth h = (lam / (w * rho)) ** 0.25, rho = points per metre (Silverman 1984); the
weights are set from that relation to get a chosen smoothing length in metres.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import BSpline, make_smoothing_spline
from scipy.ndimage import maximum_filter1d, uniform_filter1d

#: Altitude samples closer than this along the course are one (their mean altitude).
ALTITUDE_MIN_GAP_M = 1.0


def smoothing_spline(u: np.ndarray, values: np.ndarray, scale_m: np.ndarray) -> BSpline:
    """Cubic smoothing spline with a local smoothing length `scale_m` (m) per point.

    Weights follow from the equivalent-kernel bandwidth h = (lam / (w * rho)) ** 0.25.
    """
    du = np.gradient(u)
    rho = 1.0 / np.maximum(uniform_filter1d(du, 5, mode="nearest"), 1e-3)
    lam = float(np.max(scale_m)) ** 4
    return make_smoothing_spline(u, values, w=lam / (rho * scale_m**4), lam=lam)


def merge_close(s: np.ndarray, z: np.ndarray, gap_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Sorted samples (s, z) with each run closer than `gap_m` to its first made one: at
    that first s, with the run's mean z (so the samples left are `gap_m` apart at least)."""
    group = np.empty(len(s), int)
    g, first = 0, s[0]
    for i, si in enumerate(s):
        if si - first >= gap_m:
            g, first = g + 1, si
        group[i] = g
    starts = np.flatnonzero(np.diff(group, prepend=-1))
    return s[starts], np.bincount(group, z) / np.bincount(group)


def fit_altitude(s_pts: np.ndarray, z_pts: np.ndarray, length_m: float, closed: bool,
                 scale_m: float, max_grade: float) -> BSpline:
    """Smoothing spline z(s) with a long smoothing length `scale_m` (altitude jitters by
    metres); stretches steeper than `max_grade` are smoothed harder.

    Closed loops are wrapped like the plan view, positions modulo the loop (its end is its
    start). Samples closer than `ALTITUDE_MIN_GAP_M` are merged first: the fixes of a
    standing rider, projected on the line millimetres apart, made the spline's system
    singular at the long lengths (grades of -53 % and +44 % at a real ride's finish).
    """
    if closed:
        s_pts = np.mod(s_pts, length_m)
    order = np.argsort(s_pts, kind="stable")
    s, z = merge_close(s_pts[order], z_pts[order], ALTITUDE_MIN_GAP_M)
    if closed:
        pad = min(4.0 * scale_m, 0.45 * length_m)
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
    scale = np.full(len(s), scale_m)
    for _ in range(8):
        spl = smoothing_spline(s, z, scale)
        grid = np.arange(s[0], s[-1], 1.0)
        steep_grid = np.abs(spl.derivative(1)(grid)) > 0.95 * max_grade
        if not steep_grid.any():
            break
        # Data points within 50 m of a steep stretch get the longer smoothing length.
        steep = np.interp(s, grid, maximum_filter1d(steep_grid.astype(float), 101)) > 0
        scale = np.where(steep, scale * 2.0, scale)
    return spl
