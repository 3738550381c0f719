"""Map matching: a GPS fix (course ENU x, y) projected onto the course's centre line.

Matching is LOCAL while the estimator knows where the rider is: the fix is projected
only within a window around the predicted `s` (courses cross themselves, so a global
nearest point would jump to the wrong branch). A GLOBAL match, for the first fix and
for re-acquiring a lost estimator, takes the pass of the road nearest the fix and, among
passes about as near, the one nearest a preferred `s`. On a closed loop both wrap around
the seam and give cumulative progress (laps included). A rider not yet away from the
start who is within reach of it is AT the start (`start_match`): a ride's first fix is
its start, where a loop ride's finish passes a few metres away (the Ardennes ride's
first fix, 14 m before the start, matched the finish 6 m away, and the whole 2.3 h ride
was advised "finished", 2026-12-02).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from itt_planner.course.geometry import Course

#: Passes of the road whose distances to a fix differ by less than this are ambiguous
#: for a global match (GPS noise is 3-5 m; a hairpin's legs are ~2 radii apart).
_AMBIGUOUS_M = 8.0


@dataclass(frozen=True)
class Match:
    """A fix projected on the centre line: arc length, signed offset (left +)."""

    s_m: float
    n_m: float


class MapMatcher:
    """Projects fixes onto `course` (module docstring).

    Args:
        course: the course.
        search_margin_m: the local window is predicted `s` +/- (this + 4 sigma).
        global_window_m: a local window wider than this becomes a global search that
            prefers the predicted `s`.
        off_course_m: a fix farther than this beyond the road edge is off the course.
    """

    def __init__(self, course: Course, search_margin_m: float, global_window_m: float,
                 off_course_m: float) -> None:
        self.course = course
        self.search_margin_m = search_margin_m
        self.global_window_m = global_window_m
        self.off_course_m = off_course_m
        # Closed loops repeat: the last grid point duplicates the first.
        self.period_m = course.length_m if course.closed_loop else math.inf

    def wrap(self, s: float) -> float:
        """Cumulative progress as arc length on the course (one lap)."""
        return s % self.period_m if math.isfinite(self.period_m) else s

    def _project(self, idx: np.ndarray, x: float, y: float) -> tuple[int, float, float]:
        """Nearest grid point among `idx`, refined onto its tangent: (index, ds, n)."""
        c = self.course
        d2 = (c.x_m[idx] - x) ** 2 + (c.y_m[idx] - y) ** 2
        i = int(idx[int(np.argmin(d2))])
        dx, dy = x - c.x_m[i], y - c.y_m[i]
        th = c.theta_rad[i]
        along = float(np.clip(dx * math.cos(th) + dy * math.sin(th), -c.ds_m, c.ds_m))
        return i, along, float(-dx * math.sin(th) + dy * math.cos(th))

    def local(self, x: float, y: float, s_pred: float, s_var: float) -> Match | None:
        """Project within the window around the predicted `s` (variance `s_var`); None
        when off the road."""
        c = self.course
        half = self.search_margin_m + 4 * math.sqrt(s_var)
        if half > self.global_window_m:
            # So uncertain (a long gap) that a local window means little: search globally.
            return self.nearest_pass(x, y, prefer_s=s_pred)
        lo, hi = s_pred - half, s_pred + half
        n_grid = len(c.s_m)
        if math.isfinite(self.period_m):
            period_pts = n_grid - 1
            half_pts = min(int(half / c.ds_m), period_pts // 2)
            centre = round(s_pred / c.ds_m)
            idx = np.arange(centre - half_pts, centre + half_pts + 1)
            lap_idx = idx  # unwrapped index: lap count in its multiples of the period
            idx = np.mod(idx, period_pts)
        else:
            i0 = max(math.floor(lo / c.ds_m), 0)
            i1 = min(math.ceil(hi / c.ds_m), n_grid - 1)
            if i1 < i0:
                return None
            idx = lap_idx = np.arange(i0, i1 + 1)
        i, along, n = self._project(idx, x, y)
        k = int(np.flatnonzero(idx == i)[0])
        s = float(lap_idx[k] * c.ds_m + along)
        if not self._on_road(i, n):
            return None
        return Match(s, n)

    def _on_road(self, i: int, n: float) -> bool:
        c = self.course
        limit = c.width_left_m[i] if n > 0 else c.width_right_m[i]
        return bool(abs(n) <= limit + self.off_course_m)

    def start_match(self, x: float, y: float, reach_m: float) -> Match | None:
        """The start (s = 0, the fix's offset from the start's tangent) when the fix is
        within `reach_m` of the course's first point, else None."""
        c = self.course
        dx, dy = x - c.x_m[0], y - c.y_m[0]
        if math.hypot(dx, dy) > reach_m:
            return None
        th = c.theta_rad[0]
        return Match(0.0, float(-dx * math.sin(th) + dy * math.cos(th)))

    def nearest_pass(self, x: float, y: float, prefer_s: float) -> Match | None:
        """The whole course: the pass nearest the fix; if several are about as near,
        the one nearest `prefer_s`.

        Where the road passes the fix several times (a crossing, a hairpin's two legs,
        start = finish), each pass is a separate run of close grid points. Passes within
        `_AMBIGUOUS_M` of the nearest are ties; among them the arc length closest to
        `prefer_s` (ties broken towards progress) wins.
        """
        c = self.course
        d = np.hypot(c.x_m - x, c.y_m - y)
        close = d <= np.maximum(c.width_left_m, c.width_right_m) + self.off_course_m
        if not close.any():
            return None
        edges = np.flatnonzero(np.diff(np.concatenate([[0], close.astype(int), [0]])))
        base = 0.0
        if math.isfinite(self.period_m):
            base = math.floor(prefer_s / self.period_m) * self.period_m
        passes: list[Match] = []
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            i, along, n = self._project(np.arange(a, b), x, y)
            s = base + c.s_m[i] + along
            if math.isfinite(self.period_m) and s < prefer_s - self.period_m / 2:
                s += self.period_m
            passes.append(Match(float(s), n))
        nearest = min(abs(m.n_m) for m in passes)
        ties = [m for m in passes if abs(m.n_m) <= nearest + _AMBIGUOUS_M]
        return min(ties, key=lambda m: abs(m.s_m - prefer_s) + (0.0 if m.s_m >= prefer_s else 1.0))
