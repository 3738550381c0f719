"""The numeric inputs every CasADi model of the rider takes: the parameter vector
(`PARAMS`, filled by `ModelParams` for one rider and one set of conditions) and the road
data per integration interval (`ROAD`).

Everything rider- or weather-specific (mass, drag, grip, wind, ...) is a symbolic
parameter of the models (`dynamics`), not a constant, so a compiled integrator is reused
for every rider and condition.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.rider import Rider
from itt_planner.model.steady import drag_factor_kgpm

#: Road data per integration interval: mean curvature (1/m), mean slope angle (rad),
#: centre-line heading (rad, for the wind projection of E3), interval length (m).
ROAD = ("kappa", "beta", "theta", "ds")
#: Model parameters, the order of `ModelParams.vector()`.
PARAMS = ("mass", "roll_inertia", "com_height", "k_v", "crr", "wheelbase", "steer_max",
          "power_rate_max", "steer_rate_max", "cp", "p_max", "w_prime", "pedal_lean", "mu_x",
          "mu_y", "wind_e", "wind_n", "w_delta", "w_power", "efficiency")


@dataclass(frozen=True)
class ModelParams:
    """Numeric values of `PARAMS` for one rider and one set of conditions (SI units)."""

    rider: Rider
    conditions: Conditions
    w_delta: float = 0.01
    w_power: float = 0.01

    def vector(self) -> np.ndarray:
        """The parameter vector in `PARAMS` order; k_v = 0.5 rho C_D A_f (E3).

        `mu_y` is the effective lateral limit of C16, `lateral_limit_mps2 / g`: the grip,
        or the rider's own cornering limit when that is lower.
        """
        r, c = self.rider, self.conditions
        wind_e, wind_n = c.wind_enu_mps()
        return np.array([
            r.mass_kg, r.roll_inertia_kgm2, r.com_height_m,
            drag_factor_kgpm(r, c), r.crr, r.wheelbase_m, r.steer_max_rad,
            r.power_rate_max_wps, r.steer_rate_max_radps, r.critical_power_w, r.max_power_w,
            r.w_prime_j, r.pedal_lean_max_rad, c.mu_x,
            lateral_limit_mps2(r, c) / GRAVITY_MPS2, wind_e, wind_n,
            self.w_delta, self.w_power, r.drivetrain_efficiency,
        ])


def lateral_limit_mps2(rider: Rider, conditions: Conditions) -> float:
    """The lateral acceleration C16 allows: `min(mu_y g, max_lateral_accel_mps2)`."""
    grip = conditions.mu_y * GRAVITY_MPS2
    if rider.max_lateral_accel_mps2 is None:
        return grip
    return min(grip, rider.max_lateral_accel_mps2)
