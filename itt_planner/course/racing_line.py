"""The shortest line within the road, and the course of a rider who rides it.

The 1D model (model.md section 6) has no lateral dynamics: its speed does not depend on
the curvature of the path it rides, so its time-optimal path on a road of some width is
the shortest one within the road (less the C11 edge margin). On the centre line it rode
a longer course than the 3D plan, which uses the road's width on every bend: on St
John's (41.3 km, corners >= 23 m) the 3D plan's line is 0.38 % shorter than the centre
line and that length alone was worth 13.8 s of the 1D's 13.4 s deficit (bench/RESULTS.md,
2026-12-02). `line_course` gives the 1D that line as a course of its own.

- `shortest_line`: the lateral offset n(s) of the shortest line between the road edges
  less a margin, from the centre line at the start (the OCP's start, model.md section 5),
  with its heading and the stretch ds_line / ds (E8 without the speed);
- `line_course`: that line as a `Course` (its arc length is the line's; altitude, widths
  left and right of the line from the road) and the line's arc length at each point of
  the road's grid, to map a plan on the line back onto the road (`RacingLine.road_s`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from itt_planner.course.geometry import Course

log = logging.getLogger(__name__)

#: Active-set steps of the bound-constrained quadratic program, and the outer steps that
#: move its weights to the last line (the length's expansion is exact at the solution).
_ACTIVE_SET_STEPS = 200
_OUTER_STEPS = 3
#: Tolerances of the optimality test: on the offset (m) and on the multipliers (the
#: gradient's scale is the curvature times the grid step, ~1e-2 in bends).
_TOL_M = 1e-9
_TOL_SLOPE = 1e-10


@dataclass(frozen=True)
class RacingLine:
    """The shortest line of a road and the course along it.

    Attributes:
        road: the road (its centre line parametrises `n_m`).
        n_m, alpha_rad: the line's offset (positive left) and heading relative to the
            road, on the road's grid `road.s_m`.
        s_line_m: the line's arc length at each point of `road.s_m` (0 at the start).
        course: the line as a course: `course.s_m` is the line's arc length.
    """

    road: Course
    n_m: np.ndarray
    alpha_rad: np.ndarray
    s_line_m: np.ndarray
    course: Course

    @property
    def length_ratio(self) -> float:
        """Length of the line over the length of the centre line."""
        return float(self.s_line_m[-1] / self.road.length_m)

    def road_s(self, s_line_m: np.ndarray) -> np.ndarray:
        """Road (centre-line) arc length of points given by their arc length on the line."""
        out: np.ndarray = np.interp(s_line_m, self.s_line_m, self.road.s_m)
        return out

    def line_s(self, s_road_m: float | np.ndarray) -> np.ndarray:
        """Arc length on the line of points given by their road (centre-line) arc length."""
        out: np.ndarray = np.interp(s_road_m, self.road.s_m, self.s_line_m)
        return out


def _box_qp(hess: sp.csc_matrix, grad: np.ndarray, lo: np.ndarray, hi: np.ndarray,
            x0: np.ndarray) -> np.ndarray:
    """min 1/2 x'Hx + g'x on lo <= x <= hi by a primal-dual active-set method.

    For an M-matrix H (here the line's second differences) the method stops after a
    few sparse solves with the exact active set; `x0` only seeds the active sets. Where
    lo == hi the value is held. It stops when the point meets the optimality conditions
    within small tolerances (in bounds, multipliers of the right sign): the active sets
    themselves may go on switching between equivalent sets on rounding noise. Why not
    OSQP, as the least-curvature line of `ocp.guess` (fourth differences, where active
    sets cycle): on this Hessian, at the road's 1 m grid, OSQP (polished, 1e-7) took 6x
    the CPU on St John's and Bologna and stopped at 20,000 iterations on the demo courses,
    up to 1.5 m off this method's line (2026-12-02).
    """
    pinned = lo >= hi
    at_lo = (x0 <= lo) | pinned
    at_hi = (x0 >= hi) & ~at_lo
    x = x0
    for _ in range(_ACTIVE_SET_STEPS):
        free = ~(at_lo | at_hi)
        x = np.where(at_lo, lo, np.where(at_hi, hi, 0.0))
        if np.any(free):
            rhs = -grad[free] - hess[free][:, ~free] @ x[~free]
            x[free] = spla.spsolve(hess[free][:, free].tocsc(), rhs)
        slope = hess @ x + grad  # the bound multipliers where a bound holds
        if not (np.any(free & ((x < lo - _TOL_M) | (x > hi + _TOL_M)))
                or np.any(at_lo & ~pinned & (slope < -_TOL_SLOPE))
                or np.any(at_hi & (slope > _TOL_SLOPE))):
            break
        new_lo = (free & (x < lo)) | (at_lo & (slope > 0)) | pinned
        new_hi = (free & (x > hi)) | (at_hi & (slope < 0))
        at_lo, at_hi = new_lo, new_hi & ~new_lo
    else:
        log.warning("shortest line: active sets not settled after %d steps; the line is "
                    "the last one, clipped into the road", _ACTIVE_SET_STEPS)
    out: np.ndarray = np.clip(x, lo, hi)
    return out


def offset_heading_rad(n_m: np.ndarray, s_m: np.ndarray, kappa_per_m: np.ndarray
                       ) -> np.ndarray:
    """Heading relative to the road of the line at offset n(s): atan(n' / (1 - n kappa))
    (E1 of a line held at n(s))."""
    out: np.ndarray = np.arctan2(np.gradient(n_m, s_m), 1 - n_m * kappa_per_m)
    return out


def offset_stretch(n_m: np.ndarray, alpha_rad: np.ndarray, kappa_per_m: np.ndarray
                   ) -> np.ndarray:
    """ds_line / ds of a line at offset n with heading alpha: (1 - n kappa) / cos(alpha)
    (E8 without the speed)."""
    out: np.ndarray = (1 - n_m * kappa_per_m) / np.cos(alpha_rad)
    return out


def shortest_line(road: Course, margin_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The shortest line within `margin_m` of the road edges, on the road's grid: its
    offset n, heading alpha and the stretch ds_line / ds, starting on the centre line.

    The length of a line at offset n(s) is the integral of
    sqrt((1 - n kappa)^2 + n'^2) ds ~ (1 - n kappa) + n'^2 / (2 (1 - n kappa)): a
    quadratic program in n with the second differences as Hessian (a taut string between
    the edges, pulled inwards by the curvature), solved with its weights 1 / (1 - n kappa)
    at the last line a few times. The stretch is the exact one of the result (E8).
    """
    s, kappa = road.s_m, road.kappa_per_m
    h = np.diff(s)
    lo = -(road.width_right_m - margin_m)
    hi = road.width_left_m - margin_m
    lo[0] = hi[0] = 0.0  # the OCPs start on the centre line
    share = np.concatenate([[h[0] / 2], (h[1:] + h[:-1]) / 2, [h[-1] / 2]])
    rows = np.arange(len(h))
    diff = sp.csr_matrix((np.concatenate([-1 / h, 1 / h]),
                          (np.tile(rows, 2), np.concatenate([rows, rows + 1]))),
                         shape=(len(h), len(s)))
    n = np.zeros(len(s))
    for _ in range(_OUTER_STEPS):
        stretch_mid = 1 - 0.5 * (n[1:] + n[:-1]) * 0.5 * (kappa[1:] + kappa[:-1])
        hess = (diff.T @ sp.diags(h / stretch_mid) @ diff).tocsc()
        n = _box_qp(hess, -kappa * share, lo, hi, n)
    alpha = offset_heading_rad(n, s, kappa)
    return n, alpha, offset_stretch(n, alpha, kappa)


def line_course(road: Course, margin_m: float) -> RacingLine:
    """The shortest line of `road` (`shortest_line`) and the course along it
    (`offset_course`)."""
    n, _, _ = shortest_line(road, margin_m)
    return offset_course(road, n, "shortest line", {"margin_m": margin_m})


def offset_course(road: Course, n_m: np.ndarray, label: str,
                  build: dict[str, Any] | None = None) -> RacingLine:
    """The line at offset `n_m` (on the road's grid `road.s_m`, positive left) and the
    course along it: e.g. the line a 3D plan rides, for a 1D re-solve on it
    (`live.course_replan`).

    The line's course has the road's altitude at each point of the line, and the road's
    width left and right of the line; heading, curvature and slope are those of the line
    (`Course.from_centerline`), so its slope is the climb over the line's own length. The
    line's heading relative to the road is that of the offset, atan(n' / (1 - n kappa)).
    `label` names the line in the course's name; `build` goes into its build record.
    """
    n = np.asarray(n_m, float)
    alpha = offset_heading_rad(n, road.s_m, road.kappa_per_m)
    x, y, z = road.enu_at(road.s_m, n)
    s_line = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    # A grid step that ends exactly at the finish (the road's step would cut up to a step).
    steps = max(3, round(s_line[-1] / road.ds_m))
    # Heading and curvature of the line from the road's and the offset's, per road point:
    # taken from the polyline resampled onto the line's own grid they alias (the grids
    # differ by the offset's stretch).
    theta = np.unwrap(road.theta_rad + alpha)
    course = Course.from_centerline(
        f"{road.name} ({label})", x, y, z, origin=road.origin,
        theta_rad=theta, kappa_per_m=np.gradient(theta, s_line),
        closed_loop=road.closed_loop, ds_m=s_line[-1] / steps,
        width_left_m=road.width_left_m - n, width_right_m=road.width_right_m + n,
        source=road.source, source_sha256=road.source_sha256, synthetic=road.synthetic,
        build={**road.build, "line": {**(build or {}),
                                      "length_ratio": float(s_line[-1] / road.length_m)}})
    return RacingLine(road, n, alpha, s_line, course)
