"""What the virtual rider follows: a power, speed and line profile over `s` (the advice
horizon or the whole plan) with the line's slope, curvature and grip speed envelope."""

from __future__ import annotations

import math

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.live.advice import Advice
from itt_planner.model.conditions import GRAVITY_MPS2
from itt_planner.ocp.plan import Plan
from itt_planner.sim.behaviour import RiderBehaviour

#: Length over which `Reference` averages the curvature of the line it follows.
_LINE_SMOOTH_M = 8.0
#: Length over which it takes the line's slope to the road.
_SLOPE_M = 2.0
#: How much of the line it followed the rider keeps behind the start of new advice.
_LEAD_IN_M = 30.0
#: Spacing of the road-aligned grid the rider's reference is sampled on.
_GRID_M = 0.5
#: The rider never brakes for a speed below this (a walking pace).
_V_BRAKE_MIN_MPS = 1.0


def _windowed_slope(s_m: np.ndarray, y: np.ndarray, window_m: float) -> np.ndarray:
    """dy/ds at every `s_m` as the change of `y` across `window_m` centred there (cut at
    the ends), `y` linear between the points."""
    lo = np.maximum(s_m - window_m / 2, s_m[0])
    hi = np.minimum(s_m + window_m / 2, s_m[-1])
    slope: np.ndarray = (np.interp(hi, s_m, y) - np.interp(lo, s_m, y)) / np.maximum(hi - lo,
                                                                                     1e-9)
    return slope


class Reference:
    """What the rider follows: a profile over `s` (advice horizon or the whole plan), and
    the speed the rider can carry along its line within grip.

    Args:
        course: the road (the line's curvature is that of the ENU points at `(s, n)`).
        grip_lateral: fraction of `mu_y g` the rider plans to use in a steady turn.
        mu_y: lateral grip coefficient (C16).
    """

    def __init__(self, course: Course, s_m: np.ndarray, power_w: np.ndarray,
                 v_mps: np.ndarray, n_m: np.ndarray, grip_lateral: float, mu_y: float) -> None:
        grid = np.arange(math.ceil(s_m[0] / _GRID_M) * _GRID_M, s_m[-1], _GRID_M)
        if len(grid) > 2:
            # The line as a curve, sampled on a grid fixed to the road: its slope and
            # curvature are then the same whatever points a profile came as (advice
            # starts at an interpolated point; differences over the profile's own points
            # made the rider brake 2 kW where the same plan followed blindly did not).
            power_w, v_mps, n_m = (np.interp(grid, s_m, a) for a in (power_w, v_mps, n_m))
            s_m = grid
        self.s_m, self.power_w, self.v_mps, self.n_m = s_m, power_w, v_mps, n_m
        self.dn_ds = (_windowed_slope(s_m, n_m, _SLOPE_M) if len(s_m) > 2 else
                      np.gradient(n_m, s_m) if len(s_m) > 1 else np.zeros(1))
        self.v_grip = np.full(len(s_m), np.inf)
        self.kappa = np.zeros(len(s_m))
        if len(s_m) > 2:
            # Heading of the line = road heading + the line's angle to the road; its
            # change per metre travelled along the line is the line's curvature.
            one_nk = 1 - n_m * course.at("kappa_per_m", s_m)
            psi = np.unwrap(course.at("theta_rad", s_m) + np.arctan2(self.dn_ds, one_nk))
            dl_ds = np.hypot(one_nk, self.dn_ds)
            length = np.concatenate([[0.0], np.cumsum(0.5 * (dl_ds[1:] + dl_ds[:-1])
                                                      * np.diff(s_m))])
            # A rider feels the turn, not metre-scale wiggles of the sampled line: the
            # mean curvature over `_LINE_SMOOTH_M` of road, the heading change across it
            # per metre of line.
            self.kappa = (_windowed_slope(s_m, psi, _LINE_SMOOTH_M)
                          / np.maximum(_windowed_slope(s_m, length, _LINE_SMOOTH_M), 1e-6))
            # v^2 kappa <= grip_lateral mu_y g (C16 with a_x = 0).
            self.v_grip = np.sqrt(grip_lateral * mu_y * GRAVITY_MPS2
                                  / np.maximum(np.abs(self.kappa), 1e-9))

    @classmethod
    def of_plan(cls, course: Course, plan: Plan, grip_lateral: float, mu_y: float
                ) -> Reference:
        return cls(course, plan.s_m, plan.power_w, plan.v_mps, plan.n_m, grip_lateral, mu_y)

    @classmethod
    def of_advice(cls, course: Course, advice: Advice, older: Reference, grip_lateral: float,
                  mu_y: float) -> Reference:
        """The advice's profile, led in by the `older` reference's last `_LEAD_IN_M`
        before the advice starts (its line shifted to meet the new one).

        Why: advice starts at the ESTIMATED position, which GPS noise puts a few metres
        ahead of the rider as often as behind, and the line's slope and curvature at a
        profile's first points are one-sided differences. A line cut in a hairpin then
        read as a sharper turn for its first metres: the rider braked 1-2 kW there
        where the same plan followed blindly did not (bench/RESULTS.md). A rider does not
        lose the line it was following when new advice comes.
        """
        s0 = float(advice.horizon_s_m[0])
        lead = (older.s_m < s0) & (older.s_m >= s0 - _LEAD_IN_M)
        shift = float(advice.horizon_n_m[0] - np.interp(s0, older.s_m, older.n_m))
        return cls(course, np.concatenate([older.s_m[lead], advice.horizon_s_m]),
                   np.concatenate([older.power_w[lead], advice.horizon_power_w]),
                   np.concatenate([older.v_mps[lead], advice.horizon_speed_mps]),
                   np.concatenate([older.n_m[lead] + shift, advice.horizon_n_m]),
                   grip_lateral, mu_y)

    def at(self, s: float, v: float, behaviour: RiderBehaviour, decel_mps2: float
           ) -> tuple[float, float, float, float, float]:
        """Power one lag ahead, the brake speed, n and dn/ds at `s`, and the line's
        curvature `steer_preview_s` ahead (the turn the rider steers into).

        The brake speed is the lower of the advised speed's minimum a moment ahead and
        the grip envelope: the speed from which the rider can still slow, at
        `decel_mps2`, to what grip allows on the line ahead (less the brake margin,
        which the controller adds back: no tolerance on grip). No reaction distance:
        the controller's brake acts at once.
        """
        b = behaviour
        ahead = np.linspace(s, s + b.brake_lookahead_s * v, 5)
        v_ref = float(np.interp(ahead, self.s_m, self.v_mps).min())
        far = s + np.linspace(0.0, v * v / (2 * decel_mps2) + 1.0, 41)
        run = far - s
        grip = np.interp(far, self.s_m, self.v_grip, right=np.inf)
        v_env = float(np.sqrt(grip ** 2 + 2 * decel_mps2 * run).min())
        return (float(np.interp(s + b.power_lag_s * v, self.s_m, self.power_w)),
                max(min(v_ref, v_env - b.brake_margin_mps), _V_BRAKE_MIN_MPS),
                float(np.interp(s, self.s_m, self.n_m)), float(np.interp(s, self.s_m, self.dn_ds)),
                float(np.interp(s + b.steer_preview_s * v, self.s_m, self.kappa)))
