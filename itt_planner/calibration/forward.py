"""Forward simulation of the project's models with a ride's own power along its course.

The 1D model (model.md section 6, `model.build_1d`) is integrated in space with the
project's own RK4 interval (`model.rk4_step`): at each grid interval the normalised
power `W_n` is set to the ride's power there (`W_n = P / W_max`) and the speed is
carried over. The ride's other inputs (`ride_inputs`, on by default): where the ride
braked, the model brakes as a rider does, for a speed: down to the ride's speed there,
with at most the braking command `W_n < 0` inferred from the ride, and not at all if it
is already slower (a force by place would slow a model that is behind the ride by the
same force again); after a stop the replay restarts from the ride's state; launches
from a standstill and recording gaps take the ride's own figures. The result is the speed the
model predicts at every place and the time it takes, to be compared with the ride.

The 3D model is replayed through the project's virtual rider (`simulate.simulate_ride`,
E1-E9 in time): it follows the centre line, pedals the ride's power at each place,
brakes for the grip envelope of the rider's own cornering limit
(`max_lateral_accel_mps2`) and, with the ride's inputs, for the ride's speed where the
ride braked, one replay per stretch between stops; its W' balance is not allowed to cap
the measured power (the replay checks the dynamics, not the CP model).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from itt_planner.calibration.ride_data import CalibrationError
from itt_planner.calibration.ride_inputs import LAUNCH_MPS, ride_inputs
from itt_planner.calibration.ride_on_course import RideOnCourse
from itt_planner.calibration.shelter import find_shelter
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
#: Stretches between stops shorter than this are not replayed in 3D (m).
_MIN_PIECE_M = 50.0


@dataclass(frozen=True, eq=False)
class ForwardRun:
    """The model's speed and elapsed time on the ride's grid."""

    model: str
    label: str
    s_m: np.ndarray
    v_mps: np.ndarray
    t_s: np.ndarray
    ride_inputs: dict[str, Any] | None = None
    sheltered: np.ndarray | None = None

    @property
    def finish_time_s(self) -> float:
        return float(self.t_s[-1])


def forward_1d(course: Course, rider: Rider, ride: RideOnCourse,
               conditions: Conditions = Conditions(), label: str = "still air",
               ride_brakes: bool = True) -> ForwardRun:
    """The 1D model driven by the ride's power, starting at the ride's first speed (wind
    from `conditions`, projected on the road's heading as E3 does). With `ride_brakes`
    the ride's braking and stops are replayed too (`ride_inputs`): braking where the
    ride slowed faster than coasting, a restart from the ride's state after each stop,
    no time over a stretch the ride crossed in a recording gap."""
    model = build_1d()
    step = rk4_step(model, 2)
    par = ModelParams(rider, conditions).vector()
    s = ride.s_m
    mid = 0.5 * (s[1:] + s[:-1])
    kappa = course.at("kappa_per_m", mid)
    beta = course.at("beta_rad", mid)
    theta = course.at("theta_rad", mid)
    w_n = np.clip(ride.power_w, 0.0, None) / rider.max_power_w
    w_cell = 0.5 * (w_n[1:] + w_n[:-1])
    inputs = ride_inputs(model, course, rider, ride, conditions) if ride_brakes else None
    if inputs is not None:
        w_cell = np.where(inputs.brake_w_n < 0, inputs.brake_w_n, w_cell)
        label += ", ride's braking and stops"
    v = np.empty(len(s))
    t = np.zeros(len(s))
    unbraked = np.zeros(len(s) - 1, bool)
    v[0] = max(float(ride.v_mps[0]), 1.0)
    x = np.array([v[0], w_n[0], 1.0])
    for k in range(len(s) - 1):
        if inputs is not None and (inputs.unseen[k] or inputs.launch[k]):
            # A recording gap (the ride's clock did not run here; neither does the
            # model's), or a launch from a standstill: the ride's own figures.
            x[0] = v[k + 1] = max(float(ride.v_mps[k + 1]), 0.5)
            t[k + 1] = t[k] + float(ride.moving_dt_s()[k])
            continue
        road = [float(kappa[k]), float(beta[k]), float(theta[k]), float(s[k + 1] - s[k])]
        if inputs is not None and inputs.brake_w_n[k] < 0:
            x, dt, skipped = _brake_to(step, x, road, par, float(inputs.brake_w_n[k]),
                                       float(ride.v_mps[k + 1]))
            unbraked[k] = skipped
        else:
            x[1] = w_cell[k]
            xf, dt, _ = step(x, 0.0, road, par)
            x = np.asarray(xf).ravel()
        # The model has no stop: a ride that stalls on a wall is not this model's ride.
        x[0] = max(x[0], 0.5)
        x[2] = 1.0  # W' balance plays no part in replaying measured power
        if inputs is not None and inputs.stop[k]:
            x[0] = max(float(ride.v_mps[k + 1]), 1.0)  # waits, restarts as the ride did
        v[k + 1] = x[0]
        t[k + 1] = t[k] + float(dt)
    if inputs is None:
        return ForwardRun("1d", label, s, v, t)
    shelter = find_shelter(model, course, rider, ride, conditions, inputs.unexplained_w)
    summary = {**inputs.summary(ride), **shelter.summary(),
               "braking_not_needed_m": round(float(np.diff(s)[unbraked].sum()), 1)}
    return ForwardRun("1d", label, s, v, t, summary, shelter.mask)


def _brake_to(step: Any, x: np.ndarray, road: list[float], par: np.ndarray, brake_w_n: float,
              target_mps: float) -> tuple[np.ndarray, float, bool]:
    """One interval where the ride braked: the model brakes, as a rider does, for the
    ride's speed at the interval's end, with at most the ride's braking command. Already
    at or below it coasting: it does not brake (returns True: braking not needed). The
    command is interpolated in v^2 (linear in W_n over one short interval: the braking
    force is), so the end speed lands on the ride's."""
    x = x.copy()
    x[1] = 0.0
    xc, dtc, _ = step(x, 0.0, road, par)
    v_coast = float(np.asarray(xc).ravel()[0])
    if v_coast <= target_mps:
        return np.asarray(xc).ravel(), float(dtc), True
    x[1] = brake_w_n
    xb, dtb, _ = step(x, 0.0, road, par)
    v_brake = float(np.asarray(xb).ravel()[0])
    if v_brake >= target_mps:
        return np.asarray(xb).ravel(), float(dtb), False
    x[1] = brake_w_n * (v_coast ** 2 - target_mps ** 2) / (v_coast ** 2 - v_brake ** 2)
    xf, dt, _ = step(x, 0.0, road, par)
    return np.asarray(xf).ravel(), float(dt), False


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
               dt_s: float = 0.2, ride_brakes: bool = True) -> ForwardRun:
    """The 3D model (virtual rider) pedalling the ride's power along the centre line.

    Where the ride stands, launches below `LAUNCH_MPS`, crosses a recording gap or
    coasts to the line after its last pedal stroke, the ride's own figures are used
    (at walking pace the virtual rider's lean loop is unstable, and without power it
    stalls on the least rise). Without `ride_brakes`: one replay from where the ride
    first rolls at `LAUNCH_MPS` to its last pedal stroke, braking only for grip. With
    it: one replay per stretch between stops, each from the ride's state there, and
    the ride's braking: the virtual rider brakes for speeds, not forces, so where the
    ride braked (`ride_inputs`) its advised speed is the ride's speed there.

    Raises:
        CalibrationError: the virtual rider stalled or fell on more than 1 % of the
            distance it was to replay.
    """
    from itt_planner.sim import RiderBehaviour  # noqa: PLC0415

    behaviour = RiderBehaviour(power_noise=0.0)
    slow = ride.v_mps < LAUNCH_MPS
    rolling = np.flatnonzero(~slow)
    last = int(min(rolling[-1], np.flatnonzero(ride.power_w >= _PEDALLING_W)[-1]))
    own = np.ones(len(ride.s_m) - 1, bool)
    own[int(rolling[0]):last] = False
    advised = np.full(len(ride.s_m), _NO_SPEED_LIMIT_MPS)
    model = build_1d()
    inputs = ride_inputs(model, course, rider, ride, conditions) if ride_brakes else None
    if inputs is not None:
        own |= inputs.stop | inputs.unseen | inputs.launch
        braked = np.concatenate([inputs.brake_w_n < 0, [False]])
        advised[braked] = ride.v_mps[braked]
        label += ", ride's braking and stops"
    # Grip envelope = the rider's own limit: the virtual rider uses `grip_lateral` of
    # mu_y in a steady turn, so mu_y is set for that share to be the limit.
    if rider.max_lateral_accel_mps2 is not None:
        mu_y = rider.max_lateral_accel_mps2 / (behaviour.grip_lateral * GRAVITY_MPS2)
        conditions = dataclasses.replace(conditions, mu_y=min(mu_y, conditions.mu_y))
    truth = dataclasses.replace(rider, w_prime_j=1e9, max_lateral_accel_mps2=None)
    v, dt = ride.v_mps.copy(), ride.moving_dt_s().copy()
    to_replay = stalled = 0.0
    for i0, i1 in _runs(~own, ride.s_m):
        to_replay += float(ride.s_m[i1] - ride.s_m[i0])
        pv, pt = _replay_piece(course, truth, ride, conditions, advised, (i0, i1), dt_s)
        j = i0 + len(pv)
        v[i0:j], dt[i0:j - 1] = pv, np.diff(pt)
        stalled += float(ride.s_m[i1] - ride.s_m[j - 1])
    if stalled > (1.0 - _MIN_REPLAYED) * to_replay:
        raise CalibrationError(f"3D replay: the virtual rider stalled or fell on {stalled:.0f} m "
                               f"of the {to_replay:.0f} m it replayed (it stalls where the "
                               "course climbs more than the ride's power carries it, and its "
                               "lean loop is unstable at walking pace)")
    ds = np.diff(ride.s_m)
    summary: dict[str, Any] = {}
    mask = None
    if inputs is not None:
        shelter = find_shelter(model, course, rider, ride, conditions, inputs.unexplained_w)
        summary, mask = {**inputs.summary(ride), **shelter.summary()}, shelter.mask
    summary.update(replayed_m=round(to_replay - stalled, 1),
                   ride_own_m=round(float(ds[own].sum()) + stalled, 1))
    t = np.concatenate([[0.0], np.cumsum(dt)])
    return ForwardRun("3d", label, ride.s_m, v, t, summary, mask)


def _runs(mask: np.ndarray, s_m: np.ndarray) -> list[tuple[int, int]]:
    """Grid index ranges (i0, i1) of the runs of True intervals at least `_MIN_PIECE_M`
    long (interval k spans grid points k and k + 1)."""
    edges = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(int(a), int(b)) for a, b in zip(starts, ends, strict=True)
            if s_m[b] - s_m[a] >= _MIN_PIECE_M]


def _replay_piece(course: Course, truth: Rider, ride: RideOnCourse, conditions: Conditions,
                  advised: np.ndarray, span: tuple[int, int], dt_s: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The virtual rider from grid point i0 (the ride's speed there) to i1: its speed and
    time at the grid points it reached (all of them unless it stalled or fell)."""
    from itt_planner.sim import RiderBehaviour, simulate_ride  # noqa: PLC0415

    i0, i1 = span
    s0, s_end = float(ride.s_m[i0]), float(ride.s_m[i1])
    piece = _from(course, s0)
    if piece.length_m > s_end - s0 + 1.0:
        piece = dataclasses.replace(piece, **{
            k: getattr(piece, k)[: int(s_end - s0) + 1] for k in (
                "s_m", "x_m", "y_m", "z_m", "theta_rad", "kappa_per_m", "beta_rad",
                "width_left_m", "width_right_m")})
    s = piece.s_m
    arrays: dict[str, Any] = {name: np.zeros(len(s)) for name in PLAN_ARRAYS}
    speed = np.interp(s + s0, ride.s_m, advised)
    speed[0] = max(float(ride.v_mps[i0]), LAUNCH_MPS)
    arrays.update(s_m=s, power_w=np.interp(s + s0, ride.s_m, ride.power_w), v_mps=speed,
                  t_s=s / _NO_SPEED_LIMIT_MPS)
    script = Plan(model="3d", solver_status="ride replay", iterations=0, solve_time_s=0.0,
                  **arrays)
    moving = float(ride.t_moving_s[i1] - ride.t_moving_s[i0])
    sim = simulate_ride(piece, truth, script, policy="open_loop", conditions=conditions,
                        behaviour=RiderBehaviour(power_noise=0.0), dt_s=dt_s,
                        max_time_s=3.0 * moving + 120.0)
    bad = ~np.isfinite(sim.v_mps) | (sim.v_mps < 0.5) | (np.abs(sim.n_m) > _OFF_ROAD_M)
    stop = int(np.argmax(bad)) if bad.any() else len(sim.s_m)
    if stop < 2:
        return ride.v_mps[i0:i0 + 1], np.zeros(1)
    sim_s, sim_v, sim_t = sim.s_m[:stop], sim.v_mps[:stop], sim.t_s[:stop]
    keep = np.concatenate([[True], np.diff(sim_s) > 0])
    grid = ride.s_m[i0:i1 + 1] - s0
    grid = grid[grid <= sim_s[-1] + 1e-6]
    return (np.interp(grid, sim_s[keep], sim_v[keep]),
            np.interp(grid, sim_s[keep], sim_t[keep]))
