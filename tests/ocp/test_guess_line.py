"""The 3D guess's least-curvature line (`ocp.guess._line`) is the optimum of its QP: on
a 2-lap loop both laps ride the same line, through every corner to the inside edge."""

from __future__ import annotations

import numpy as np
from support.courses import loop_4k_lap

from itt_planner.course.builder import build_course
from itt_planner.ocp.guess import _LINE_MARGIN_M, _line

#: Issue 18's 4 km loop, two laps: four corners of 20 m a lap.
LOOP = build_course({"name": "loop-4k-2laps", "segments": loop_4k_lap() + loop_4k_lap()})


def test_both_laps_ride_the_same_line_to_the_inside_edge() -> None:
    """The active-set method of before cycled on this QP (its Hessian is not an
    M-matrix) and stopped at its step cap with the two laps' lines 0.9 m apart in the
    first three corners (4,040 nodes, 2 m apart); the QP's optimum rides them alike
    (within the interpolation between nodes: a lap is not a whole number of steps)."""
    nodes = np.linspace(0.0, LOOP.length_m, 4040)
    n, alpha, curvature = _line(LOOP, nodes)
    lap = LOOP.length_m / 2
    s = np.linspace(800.0, 3000.0, 2000)  # corners 1-3, far from the start and the finish
    assert np.max(np.abs(np.interp(s, nodes, n) - np.interp(s + lap, nodes, n))) < 0.1
    # Every corner (left turns) touches the inside edge less the margin at its apex.
    inside = LOOP.width_left_m[0] - _LINE_MARGIN_M
    corner = np.abs(LOOP.at("kappa_per_m", nodes)) > 0.5 / 20.0
    starts = np.flatnonzero(corner[1:] & ~corner[:-1]) + 1
    ends = np.flatnonzero(~corner[1:] & corner[:-1]) + 1
    assert len(starts) == len(ends) == 8
    for a, b in zip(starts, ends, strict=True):
        assert np.max(n[a:b]) > inside - 0.01
    assert np.all(np.isfinite(alpha)) and np.all(np.isfinite(curvature))
    # Least curvature: the line turns more gently than the road's 20 m corners.
    assert np.max(np.abs(curvature)) < 0.8 / 20.0
