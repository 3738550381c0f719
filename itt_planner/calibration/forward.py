"""Forward simulation of the project's models with a ride's own power along its course.

The 1D model (model.md section 6, `model.build_1d`) is integrated in space with the
project's own RK4 interval (`model.rk4_step`): at each grid interval the normalised
power `W_n` is set to the ride's power there (`W_n = P / W_max`, no braking: the ride's
braking is not measured) and the speed is carried over. The result is the speed the
model predicts at every place and the time it takes, to be compared with the ride.

The 3D model is replayed through the project's virtual rider (`simulate.simulate_ride`,
E1-E9 in time): it follows the centre line, pedals the ride's power at each place,
and brakes only for the grip envelope of the rider's own cornering limit
(`max_lateral_accel_mps2`); its W' balance is not allowed to cap the measured power
(the replay checks the dynamics, not the CP model).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from itt_planner.calibration.ride_data import CalibrationError
from itt_planner.calibration.ride_on_course import RideOnCourse
from itt_planner.course.geometry import Course, detect_corners
from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.dynamics import build_1d, rk4_step
from itt_planner.model.params import ModelParams
from itt_planner.model.rider import Rider
from itt_planner.ocp.plan import PLAN_ARRAYS, Plan

#: The virtual rider's advised speed in the replay: high, so it brakes only for grip.
_NO_SPEED_LIMIT_MPS = 30.0
#: A replay that leaves the centre line by more than this has fallen (m).
_OFF_ROAD_M = 20.0
#: Share of the stretch a 3D replay must cover before stalling to count.
_MIN_REPLAYED = 0.99
#: Power below this is not pedalling (W).
_PEDALLING_W = 40.0
#: Lowest start speed of the 3D replay (m/s).
_START_MIN_MPS = 3.0


@dataclass(frozen=True, eq=False)
class ForwardRun:
    """The model's speed and elapsed time on the ride's grid."""

    model: str
    label: str
    s_m: np.ndarray
    v_mps: np.ndarray
    t_s: np.ndarray

    @property
    def finish_time_s(self) -> float:
        return float(self.t_s[-1])


def forward_1d(course: Course, rider: Rider, ride: RideOnCourse,
               conditions: Conditions = Conditions(), label: str = "still air") -> ForwardRun:
    """The 1D model driven by the ride's power, starting at the ride's first speed (wind
    from `conditions`, projected on the road's heading as E3 does)."""
    model = build_1d()
    step = rk4_step(model, 2)
    par = ModelParams(rider, conditions).vector()
    s = ride.s_m
    mid = 0.5 * (s[1:] + s[:-1])
    kappa = course.at("kappa_per_m", mid)
    beta = course.at("beta_rad", mid)
    theta = course.at("theta_rad", mid)
    w_n = np.clip(ride.power_w, 0.0, None) / rider.max_power_w
    v = np.empty(len(s))
    t = np.zeros(len(s))
    v[0] = max(float(ride.v_mps[0]), 1.0)
    x = np.array([v[0], w_n[0], 1.0])
    for k in range(len(s) - 1):
        x[1] = 0.5 * (w_n[k] + w_n[k + 1])
        road = [float(kappa[k]), float(beta[k]), float(theta[k]), float(s[k + 1] - s[k])]
        xf, dt, _ = step(x, 0.0, road, par)
        x = np.asarray(xf).ravel()
        # The model has no stop: a ride that stalls on a wall is not this model's ride.
        x[0] = max(x[0], 0.5)
        x[2] = 1.0  # W' balance plays no part in replaying measured power
        v[k + 1] = x[0]
        t[k + 1] = t[k] + float(dt)
    return ForwardRun("1d", label, s, v, t)


def _from(course: Course, s0: float) -> Course:
    """The course from arc length `s0` on (re-anchored at s = 0, corners re-detected)."""
    i0 = int(np.searchsorted(course.s_m, s0))
    arrays = {k: getattr(course, k)[i0:] for k in ("x_m", "y_m", "z_m", "theta_rad",
                                                   "kappa_per_m", "beta_rad", "width_left_m",
                                                   "width_right_m")}
    s = course.s_m[i0:] - course.s_m[i0]
    return dataclasses.replace(course, s_m=s, corners=detect_corners(s, arrays["kappa_per_m"]),
                               closed_loop=False, **arrays)


def forward_3d(course: Course, rider: Rider, ride: RideOnCourse,
               conditions: Conditions = Conditions(), label: str = "still air",
               dt_s: float = 0.2) -> ForwardRun:
    """The 3D model (virtual rider) pedalling the ride's power along the centre line, from
    where the ride first rolls at `_START_MIN_MPS` to its last pedal stroke (before and
    after, standing or coasting to a stop at the line, the ride's own figures are used:
    the replay has no power there and stalls on the least rise).

    Raises:
        CalibrationError: the virtual rider stalled or fell (no finish): at walking pace
            its lean loop is unstable, and a measured stop (a junction on a climb) stops it.
    """
    from itt_planner.sim import RiderBehaviour, simulate_ride  # noqa: PLC0415

    behaviour = RiderBehaviour(power_noise=0.0)
    rolling = np.flatnonzero(ride.v_mps >= _START_MIN_MPS)
    pedalling = np.flatnonzero(ride.power_w >= _PEDALLING_W)
    i0, i1 = int(rolling[0]), int(min(rolling[-1], pedalling[-1]))
    s0, s_end = float(ride.s_m[i0]), float(ride.s_m[i1])
    course = _from(course, s0)
    if course.length_m > s_end - s0 + 1.0:
        course = dataclasses.replace(course, **{
            k: getattr(course, k)[: int(s_end - s0) + 1] for k in (
                "s_m", "x_m", "y_m", "z_m", "theta_rad", "kappa_per_m", "beta_rad",
                "width_left_m", "width_right_m")})
    s = course.s_m
    power = np.interp(s + s0, ride.s_m, ride.power_w)
    arrays: dict[str, Any] = {name: np.zeros(len(s)) for name in PLAN_ARRAYS}
    speed = np.full(len(s), _NO_SPEED_LIMIT_MPS)
    # The virtual rider's lean loop is unstable at walking pace (it diverged within 40 m
    # from 1 m/s on a real start): it starts rolling; the extra kinetic energy is ~0.5 kJ.
    speed[0] = max(float(ride.v_mps[i0]), _START_MIN_MPS)
    arrays.update(s_m=s, power_w=power, v_mps=speed, t_s=s / _NO_SPEED_LIMIT_MPS)
    script = Plan(model="3d", solver_status="ride replay", iterations=0, solve_time_s=0.0,
                  **arrays)
    # Grip envelope = the rider's own limit: the virtual rider uses `grip_lateral` of
    # mu_y in a steady turn, so mu_y is set for that share to be the limit.
    truth = dataclasses.replace(rider, w_prime_j=1e9, max_lateral_accel_mps2=None)
    if rider.max_lateral_accel_mps2 is not None:
        mu_y = rider.max_lateral_accel_mps2 / (behaviour.grip_lateral * GRAVITY_MPS2)
        conditions = dataclasses.replace(conditions, mu_y=min(mu_y, conditions.mu_y))
    sim = simulate_ride(course, truth, script, policy="open_loop", conditions=conditions,
                        behaviour=behaviour, dt_s=dt_s, max_time_s=3.0 * ride.moving_time_s + 600)
    bad = ~np.isfinite(sim.v_mps) | (sim.v_mps < 0.5) | (np.abs(sim.n_m) > _OFF_ROAD_M)
    stop = int(np.argmax(bad)) if bad.any() else len(sim.s_m)
    reached = float(sim.s_m[stop - 1]) if stop > 0 else 0.0
    if reached < _MIN_REPLAYED * (s_end - s0):
        raise CalibrationError(f"3D replay: the virtual rider stalled or fell near "
                               f"{reached + s0:.0f} m of {s_end:.0f} m (at walking pace its lean "
                               "loop is unstable; a stop in the ride stops it)")
    # A stall in the last metres (coasting up to the line): compared up to there.
    i1 = min(i1, int(np.searchsorted(ride.s_m, reached + s0)) - 1)
    sim_s, sim_v, sim_t = sim.s_m[:stop], sim.v_mps[:stop], sim.t_s[:stop]
    keep = np.concatenate([[True], np.diff(sim_s) > 0])
    grid = ride.s_m[i0:i1 + 1]
    v = np.interp(grid - s0, sim_s[keep], sim_v[keep])
    t = np.interp(grid - s0, sim_s[keep], sim_t[keep]) + ride.t_moving_s[i0]
    # Before and after the replay (standing or coasting at the lines) the ride's figures.
    v = np.concatenate([ride.v_mps[:i0], v, ride.v_mps[i1 + 1:]])
    t = np.concatenate([ride.t_moving_s[:i0], t, ride.t_moving_s[i1 + 1:] - ride.t_moving_s[i1]
                        + t[-1]]) - ride.t_moving_s[0]
    label = label if i1 + 1 == len(ride.s_m) else (
        f"{label}, replayed to {ride.s_m[i1]:.0f} of {ride.s_m[-1]:.0f} m")
    return ForwardRun("3d", label, ride.s_m, v, t)
