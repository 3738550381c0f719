"""The ride's own inputs for a forward replay: where it braked, and where it stood.

A replay drives the model with what the rider did. Power is measured; braking is not,
but the ride shows it: where the ride slows faster than the model coasting at zero
power allows at the ride's own speed, something else took the energy, and on a road
that is the rider's brakes. Over one grid interval of length `ds`, with the ride's
speeds `v0`, `v1` at its ends and `v = (v0 + v1)/2`:

    a_ride  = (v1^2 - v0^2) / (2 ds)                       (the ride's dv/dt)
    a_coast = dv/dt of E3 at v, W_n = 0                    (grade, rolling, drag, wind)
    W_n     = (a_ride - a_coast) / (mu_x g)   where a_ride < a_coast - BRAKE_MARGIN_MPS2

The model's braking control is `W_n < 0`, a tyre force `mu_x g m W_n` (E3, section 2 of
model.md), so that `W_n` makes the model, at the ride's speed, slow exactly as the ride
did; the replay brakes there in place of the ride's power (a rider does not pedal
against the brakes; what little power the meter saw is dissipated too), for the ride's
speed with at most this command (`forward`: a rider brakes for a speed, not by place).
The margin
keeps speed noise from reading as braking: below it a deceleration is within what the
5 s smoothed speed differentiated over one interval scatters by (`BRAKE_MARGIN_MPS2`).

Stops: where the ride stood (speed below `MOVING_MPS`) for `STOP_MIN_S` or more in one
interval, or crossed a recording gap, the replay waits there and restarts from the
ride's state (its speed after the stop): nothing of the model's speed is carried
through a junction, and the ride's power is not replayed by place through it. Over an
interval the ride crossed without a moving clock (a recording gap with the rider
moving), neither the ride's nor the model's time counts.

Unexplained power: over the intervals the replay drives with the ride's power (no
braking, stop, launch or gap), `m v (a_ride - a_model)`, with `a_model` the model's E3
at the ride's speed and power, is the power the ride got that the model does not
explain (gusts and shelter, drafting, a tuck, light braking under the margin, elevation
errors). Averaged over braking-free windows of `UNEXPLAINED_WINDOW_M` (where speed
noise telescopes to a few W), its spread is what keeps a replay's speed from the
ride's: 40 W at 35 km/h is ~2 km/h of steady speed for a rider of CdA 0.4.

Launches: from the start and from each stop until the ride first rolls at
`LAUNCH_MPS`, and from where it slows below it up to a stop, the replay takes the
ride's own speed and time. At walking pace a replay
by place is ill-posed: the meter's 1 Hz power lags the first pedal strokes (St John's
rolls from 1.7 to 3.7 m/s over 15 m with 0 W recorded), so a model started there
crawls at its speed floor and loses a minute in the first 100 m. The distance so
taken is counted (`launch_m`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import casadi as ca
import numpy as np

from itt_planner.calibration.ride_on_course import RideOnCourse
from itt_planner.course.geometry import Course
from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.dynamics import SpatialModel
from itt_planner.model.params import ModelParams
from itt_planner.model.rider import Rider

#: Deceleration beyond coasting (m/s^2) below which a slowing is read as speed noise.
BRAKE_MARGIN_MPS2 = 0.3
#: Power above which the rider is surely pedalling, not braking (W): the noise sample.
PEDALLING_HARD_W = 100.0
#: Standing (or a paused record) this long within one interval is a stop (s).
STOP_MIN_S = 3.0
#: A launch (start, restart after a stop) is the ride's own until it rolls this fast (m/s).
LAUNCH_MPS = 3.0
#: Window of the unexplained-power figure (m).
UNEXPLAINED_WINDOW_M = 500.0
#: An interval the ride crossed in less moving time than this was not seen moving (s).
_UNSEEN_S = 1e-6


@dataclass(frozen=True, eq=False)
class RideInputs:
    """Per grid interval of a `RideOnCourse`: braking command, stops and unseen stretches.

    Attributes:
        brake_w_n: the model's braking control `W_n` (<= 0; 0 where the ride did not brake).
        stop: the ride stood (or paused) in this interval: restart from its state after.
        unseen: the ride crossed this interval with no moving clock (recording gap).
        launch: the ride was below `LAUNCH_MPS` launching from the start or a stop, or
            rolling up to a stop: the replay takes the ride's own speed and time here.
        unexplained_w: power the ride got beyond the model's at the ride's speed and
            power (module docstring); NaN where the replay does not use the ride's power.
    """

    brake_w_n: np.ndarray
    stop: np.ndarray
    unseen: np.ndarray
    launch: np.ndarray
    unexplained_w: np.ndarray

    def summary(self, ride: RideOnCourse) -> dict[str, float | int]:
        """Counts for the report: braking distance, stops, unseen and launch distance,
        and the unexplained power over windows (mean and spread of the window means)."""
        ds = np.diff(ride.s_m)
        braking = self.brake_w_n < 0
        starts = np.flatnonzero(self.stop & ~np.concatenate([[False], self.stop[:-1]]))
        windows = window_means(self.unexplained_w, 0.5 * (ride.v_mps[1:] + ride.v_mps[:-1]),
                               ds, UNEXPLAINED_WINDOW_M)
        out: dict[str, float | int] = {
            "braking_m": round(float(ds[braking].sum()), 1),
            "braking_share": round(float(ds[braking].sum() / ds.sum()), 4),
            "stops": len(starts),
            "unseen_m": round(float(ds[self.unseen].sum()), 1),
            "launch_m": round(float(ds[self.launch].sum()), 1),
            "unexplained_windows": len(windows)}
        if len(windows) >= 2:
            out.update(unexplained_mean_w=round(float(windows.mean()), 1),
                       unexplained_sd_w=round(float(windows.std()), 1))
        return out


def window_means(values: np.ndarray, v_mps: np.ndarray, ds_m: np.ndarray, window_m: float
                 ) -> np.ndarray:
    """Time-weighted means of `values` over consecutive windows of `window_m` of
    intervals (lengths `ds_m`, speeds `v_mps`), skipping windows with a NaN."""
    n = max(round(window_m / float(np.mean(ds_m))), 1)
    out = []
    for i in range(0, len(values) - n + 1, n):
        x, dt = values[i:i + n], ds_m[i:i + n] / np.maximum(v_mps[i:i + n], 0.5)
        if np.isfinite(x).all():
            out.append(float(np.sum(x * dt) / np.sum(dt)))
    return np.array(out)


def coasting_accel_mps2(model: SpatialModel, course: Course, rider: Rider,
                        conditions: Conditions, s_m: np.ndarray, v_mps: np.ndarray,
                        power_w: np.ndarray | None = None) -> np.ndarray:
    """dv/dt of the model's E3 at speed `v_mps` at places `s_m`, not pedalling (W_n = 0),
    or pedalling `power_w`."""
    par = ModelParams(rider, conditions).vector()
    road = np.vstack([course.at("kappa_per_m", s_m), course.at("beta_rad", s_m),
                      course.at("theta_rad", s_m), np.ones(len(s_m))])
    w_n = np.zeros(len(s_m)) if power_w is None else np.asarray(power_w) / rider.max_power_w
    x = np.vstack([np.asarray(v_mps, float), w_n, np.ones(len(s_m))])
    ode = model.ode.map(len(s_m))
    dx_ds, _, _ = ode(x, np.zeros((model.nu, len(s_m))), road, np.tile(par, (len(s_m), 1)).T)
    # Spatial ODE: dv/ds; in time dv/dt = v dv/ds.
    return cast(np.ndarray, np.asarray(ca.DM(dx_ds)[0, :]).ravel() * x[0])


def ride_inputs(model: SpatialModel, course: Course, rider: Rider, ride: RideOnCourse,
                conditions: Conditions) -> RideInputs:
    """Braking, stops and unseen intervals of `ride` for a replay in `conditions` (the
    module docstring's equations)."""
    s, v = ride.s_m, ride.v_mps
    ds = np.diff(s)
    v_mid = np.maximum(0.5 * (v[1:] + v[:-1]), 0.5)
    a_ride = (v[1:] ** 2 - v[:-1] ** 2) / (2.0 * ds)
    a_coast = coasting_accel_mps2(model, course, rider, conditions, 0.5 * (s[1:] + s[:-1]),
                                  v_mid)
    excess = a_ride - a_coast
    margin = brake_margin_mps2(excess, ride, rider, v_mid)
    brake = np.where(excess < -margin,
                     np.maximum(excess / (conditions.mu_x * GRAVITY_MPS2), -1.0), 0.0)
    unseen = ride.moving_dt_s() < _UNSEEN_S
    stop = (ride.stopped_dt_s() >= STOP_MIN_S) | unseen
    launch = _launches(stop, (v[1:] < LAUNCH_MPS) | (v[:-1] < LAUNCH_MPS))
    power = np.clip(0.5 * (ride.power_w[1:] + ride.power_w[:-1]), 0.0, None)
    a_model = coasting_accel_mps2(model, course, rider, conditions, 0.5 * (s[1:] + s[:-1]),
                                  v_mid, power)
    unexplained = rider.mass_kg * v_mid * (a_ride - a_model)
    replayed = (brake == 0.0) & ~stop & ~launch
    return RideInputs(brake_w_n=brake, stop=stop, unseen=unseen, launch=launch,
                      unexplained_w=np.where(replayed, unexplained, np.nan))


def brake_margin_mps2(excess: np.ndarray, ride: RideOnCourse, rider: Rider,
                      v_mid: np.ndarray) -> float:
    """How far the ride's acceleration scatters above the model's where the rider pedals
    (no one brakes there): the 95th percentile of the ride's acceleration minus the
    model's with the ride's power, at least `BRAKE_MARGIN_MPS2`."""
    power = 0.5 * (ride.power_w[1:] + ride.power_w[:-1])
    pedalling = power >= PEDALLING_HARD_W
    if pedalling.sum() < 100:
        return BRAKE_MARGIN_MPS2
    scatter = (excess - rider.drivetrain_efficiency * power / (rider.mass_kg * v_mid))[pedalling]
    return max(float(np.percentile(scatter, 95)), BRAKE_MARGIN_MPS2)


def _launches(stop: np.ndarray, slow: np.ndarray) -> np.ndarray:
    """Intervals at walking pace (`slow`) joined to the start or to a stop: launching
    from it, or rolling up to it."""
    launch = np.zeros(len(stop), bool)
    for order in (range(len(stop)), range(len(stop) - 1, -1, -1)):
        active = order.start == 0  # the start is a launch; the finish is not
        for k in order:
            if stop[k]:
                active = True
                continue
            active = active and bool(slow[k])
            launch[k] |= active
    return launch
