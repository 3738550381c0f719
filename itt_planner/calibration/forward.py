"""Forward simulation of the project's models with a ride's own power along its course.

The 1D model (model.md section 6, `model.build_1d`) is integrated in space with the
project's own RK4 interval (`model.rk4_step`): at each grid interval the normalised
power `W_n` is set to the ride's power there (`W_n = P / W_max`, no braking: the ride's
braking is not measured) and the speed is carried over. The result is the speed the
model predicts at every place and the time it takes, to be compared with the ride.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from itt_planner.calibration.ride_on_course import RideOnCourse
from itt_planner.conditions import Conditions
from itt_planner.course import Course
from itt_planner.model import ModelParams, build_1d, rk4_step
from itt_planner.rider import Rider


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
