"""Stretches of a track without fixes: the course runs straight across them.

A GPS that lost the sky (a tunnel, a device switched off, a log split in several) leaves
a chord of hundreds of metres to kilometres between two fixes. A smoothing spline through
the fixes at its ends (`fit._smooth`, whose weights grow where fixes are sparse) swings
wide of that chord: on the real rides 100 m off a 748 m gap (Sauerland) and 132 m off a
648 m one (Shanghai); on a GPS log of four recordings with 1.4-5.4 km between them
(gpxpy's `cerknicko-jezero.gpx`) the fitted course came out 13.0 km long for 9.5 km of
fixes. Nothing says where the road went there, and the straight line is the shortest
guess, so each such chord is filled with points on it before the fit, and reported.

A chord is long against the track's own spacing: a route drawn with a point every 150 m
along gentle bends keeps its smooth fit (filled, each vertex would become a kink), while
a route with points only at the corners gets straight roads between them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

#: A chord longer than this (m) ...
GAP_MIN_M = 100.0
#: ... and than this many times the track's median spacing is a gap.
GAP_FACTOR = 8.0
#: The spline's own course near a gap's ends (m): it turns into the road beyond, as it
#: would on a straight pinned up to a corner's first fix only too late.
GAP_END_M = 30.0
#: Gaps from this long (m) are warned about, the shorter ones only listed.
GAP_WARN_M = 300.0


@dataclass(frozen=True)
class Gap:
    """A chord between two consecutive fixes with no fix on it.

    Attributes:
        fix: index of the fix it starts from (the next one ends it).
        length_m: the chord's length.
        duration_s: the time between the two fixes (None for a route without times).
    """

    fix: int
    length_m: float
    duration_s: float | None


def find_gaps(xy: np.ndarray, time_s: np.ndarray | None = None) -> list[Gap]:
    """The chords of the polyline `xy` (n x 2, m) long enough to be gaps (module docstring)."""
    step = np.hypot(*np.diff(xy, axis=0).T)
    if len(step) == 0:
        return []
    limit = max(GAP_MIN_M, GAP_FACTOR * float(np.median(step)))
    return [Gap(int(i), float(step[i]),
                None if time_s is None or not np.isfinite(time_s[i:i + 2]).all()
                else float(time_s[i + 1] - time_s[i]))
            for i in np.flatnonzero(step > limit)]


def fill_gaps(u: np.ndarray, xy: np.ndarray, min_points: int = 5
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points on each gap's chord (`u`: the parameter along the polyline `xy`), a step of
    the track's median spacing (2-20 m) apart, but none within `GAP_END_M` of its ends;
    a track of fewer than `min_points` (what `make_smoothing_spline` needs) is densified
    to that many the same way, ends included.

    Returns the new parameters and points, and where each input point went in them.
    """
    span = np.diff(u)
    if len(u) < min_points:  # every chord, ends included
        chords, step_m, end_m = (np.arange(len(span)), float(u[-1] - u[0]) / (min_points - 1),
                                 0.0)
    else:
        chords = np.array([g.fix for g in find_gaps(xy)], int)
        step_m, end_m = float(np.clip(np.median(span), 2.0, 20.0)), GAP_END_M
    fracs = {int(i): _fractions(float(span[i]), step_m, end_m) for i in chords}
    fracs = {i: f for i, f in fracs.items() if len(f)}
    extra = np.zeros(len(span), int)
    for i, f in fracs.items():
        extra[i] = len(f)
    at = np.arange(len(u)) + np.concatenate([[0], np.cumsum(extra)])
    u_new, xy_new = np.empty(at[-1] + 1), np.empty((at[-1] + 1, 2))
    u_new[at], xy_new[at] = u, xy
    for i, f in fracs.items():
        u_new[at[i] + 1: at[i + 1]] = u[i] + f * span[i]
        xy_new[at[i] + 1: at[i + 1]] = xy[i] + f[:, None] * (xy[i + 1] - xy[i])
    return u_new, xy_new, at


def _fractions(span_m: float, step_m: float, end_m: float) -> np.ndarray:
    """Where points go on a chord of `span_m`, as fractions of it: at most `step_m` apart,
    from `end_m` to `span_m - end_m` with both ends when `end_m` > 0, else strictly
    inside the chord."""
    inner_m = span_m - 2 * end_m
    if end_m:
        n = int(np.ceil(inner_m / step_m)) + 1
        return (end_m + np.linspace(0.0, inner_m, n)) / span_m
    n = int(np.ceil(inner_m / step_m)) - 1
    return np.arange(1, n + 1) / (n + 1)


def gap_report(xy: np.ndarray, time_s: np.ndarray | None, s_fix_m: np.ndarray, stamped: bool
               ) -> tuple[list[dict[str, Any]], list[str]]:
    """The gaps of a course's fixes (`s_fix_m` along it) as `Course.build` lists them, and a
    warning on those worth checking (none or one). Only a GPS log (`stamped`) is warned
    about: a route drawn on a map has a point at each end of a straight, and means it."""
    gaps = find_gaps(xy, time_s)
    s_start_m = s_fix_m[[g.fix for g in gaps]]
    rows = [{"at_m": round(float(s), 1), "length_m": round(g.length_m, 1),
             "duration_s": g.duration_s} for g, s in zip(gaps, s_start_m, strict=True)]
    warning = _warning([(g, s) for g, s in zip(gaps, s_start_m, strict=True)
                        if stamped and g.length_m >= GAP_WARN_M])
    return rows, [warning] if warning else []


def _warning(long: list[tuple[Gap, float]]) -> str | None:
    if not long:
        return None
    g, s = max(long, key=lambda gs: gs[0].length_m)
    when = "" if g.duration_s is None else f" in {g.duration_s:.0f} s"
    return (f"{len(long)} stretch{'es' if len(long) > 1 else ''} of the track without a fix "
            f"over {GAP_WARN_M:.0f} m (longest {g.length_m:.0f} m{when} at {s / 1000:.2f} km): "
            "the course runs straight across them; check them (--route)")
