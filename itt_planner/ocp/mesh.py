"""The non-uniform spatial mesh of the OCPs, and the road data per mesh interval.

Spacing follows what the solution needs to resolve: about 1 m where the road bends
tightly (a hairpin's heading turns by at most ~0.1 rad per interval), finer where the
slope changes, at the launch, and coarse (up to `h_max_m`) on straights. The spacing may
change by at most `grade` metres per metre, so the fine zone spreads into the braking
and acceleration zones around a corner instead of ending abruptly at its entry.

Where the rider is slow the spacing also follows the speed (`speed_spacing_m`): in the
spatial domain `dv/ds = a / v`, whose stiffness `~2 a / v^2` grows without bound as the
speed falls, so a fixed step that is fine at 10 m/s is unstable at 1 m/s (issue 18: one
RK4 step of 10 m from 0.5 m/s made 580 m/s). The launch gets a few tens of centimetres,
a steep climb ridden slowly a metre or two, fast road nothing.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from itt_planner.course.geometry import Course

#: Largest heading change per interval (rad): ~1.2 m in a 12 m hairpin.
_TURN_PER_INTERVAL_RAD = 0.1
#: Largest slope-angle change per interval (rad).
_SLOPE_CHANGE_PER_INTERVAL_RAD = 0.01


#: Finest spacing the speed rule may ask for (m).
_H_FLOOR_M = 0.05


def speed_spacing_m(v_mps: np.ndarray, accel_mps2: np.ndarray) -> np.ndarray:
    """Largest step that keeps one RK4 step of `dv/ds = a/v` well inside its stability
    region: `h * 2 a / v^2 <= 1` (RK4 is stable to 2.78), for speeds `v_mps` and tyre
    accelerations (force per unit mass) `accel_mps2`."""
    h: np.ndarray = np.asarray(v_mps) ** 2 / (2 * np.maximum(np.abs(accel_mps2), 1e-6))
    return h


def split_spacing_m(grid_s_m: np.ndarray, nodes: np.ndarray, starts_s_m: Sequence[float]
                    ) -> np.ndarray:
    """Spacing cap on the grid `grid_s_m` that splits each interval of `nodes` starting at
    one of `starts_s_m` in two (half its length on the grid points around it, so that
    the cap read at its start is that), no cap elsewhere: where a plan's step did not
    resolve its dynamics (`verify.Verification.unresolved_s_m`; an RK4 step's error
    falls as h^5)."""
    cap = np.full(len(grid_s_m), np.inf)
    i = np.searchsorted(nodes, np.asarray(starts_s_m, float))
    for a, b in zip(nodes[i], nodes[np.minimum(i + 1, len(nodes) - 1)], strict=True):
        lo = max(int(np.searchsorted(grid_s_m, a, side="right")) - 1, 0)
        hi = int(np.searchsorted(grid_s_m, b, side="right")) + 1
        cap[lo:hi] = np.minimum(cap[lo:hi], 0.5 * (b - a))
    return cap


def target_spacing(course: Course, h_min_m: float, h_max_m: float, grade: float = 0.25,
                   launch_m: float = 30.0, h_cap_m: np.ndarray | None = None) -> np.ndarray:
    """Wanted interval length at every point of the course grid (m).

    `h_cap_m` (on the course grid): a further cap, e.g. `speed_spacing_m`; it may go
    below `h_min_m` (down to 5 cm).
    """
    ds = course.ds_m
    kappa = np.abs(course.kappa_per_m)
    dbeta = np.abs(np.gradient(course.beta_rad, course.s_m))
    with np.errstate(divide="ignore", over="ignore"):  # straight or even: no limit (inf)
        h = np.minimum(_TURN_PER_INTERVAL_RAD / kappa, _SLOPE_CHANGE_PER_INTERVAL_RAD / dbeta)
    # Launch: the propulsive force P/v is largest at the slowest speeds (model.md C16 note).
    h = np.minimum(h, h_min_m + course.s_m * (h_max_m / launch_m))
    h = np.clip(h, h_min_m, h_max_m)
    if h_cap_m is not None:
        h = np.minimum(h, np.maximum(h_cap_m, _H_FLOOR_M))
    return _graded(h, ds, grade)


def _graded(h: np.ndarray, ds: float, grade: float) -> np.ndarray:
    """Limit |dh/ds| <= grade with a forward and a backward sweep."""
    h = np.array(h, dtype=float)
    step = grade * ds
    for i in range(1, len(h)):
        h[i] = min(h[i], h[i - 1] + step)
    for i in range(len(h) - 2, -1, -1):
        h[i] = min(h[i], h[i + 1] + step)
    return h


def build_mesh(course: Course, h_min_m: float = 1.0, h_max_m: float = 10.0,
               uniform_m: float | None = None, start_m: float = 0.0,
               end_m: float | None = None, h_cap_m: np.ndarray | None = None) -> np.ndarray:
    """Node positions `s` from `start_m` to `end_m` (default: the whole course).

    `h_cap_m`: see `target_spacing`. A uniform mesh honours it too (it is then uniform
    except where the rider is too slow for `uniform_m`, e.g. the first metres).
    """
    end = course.length_m if end_m is None else end_m
    if uniform_m is not None:
        if h_cap_m is None or np.all(h_cap_m >= uniform_m):
            n = max(1, round((end - start_m) / uniform_m))
            return np.linspace(start_m, end, n + 1)
        h = _graded(np.minimum(np.maximum(h_cap_m, _H_FLOOR_M), uniform_m), course.ds_m, 0.25)
    else:
        h = target_spacing(course, h_min_m, h_max_m, h_cap_m=h_cap_m)
    nodes = [start_m]
    s = start_m
    while end - s > 1e-9:
        step = float(np.interp(s, course.s_m, h))
        # Do not leave a sliver of an interval before the end.
        s = end if end - s < 1.5 * step else s + step
        nodes.append(s)
    return np.asarray(nodes)


def road_data(course: Course, nodes: np.ndarray) -> np.ndarray:
    """Road data per interval (`model.ROAD` rows x len(nodes)-1 columns).

    The mean curvature is the exact heading change over the interval divided by its
    length, so the discrete road turns by exactly as much as the real one; the slope is
    the mean grade; the heading (for the wind, E3) is taken at the interval's middle.
    """
    ds = np.diff(nodes)
    theta = course.at("theta_rad", nodes)
    z = course.at("z_m", nodes)
    kappa = np.diff(theta) / ds
    beta = np.arctan(np.diff(z) / ds)
    theta_mid = course.at("theta_rad", 0.5 * (nodes[1:] + nodes[:-1]))
    return np.vstack([kappa, beta, theta_mid, ds])
