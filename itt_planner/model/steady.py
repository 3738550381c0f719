"""The E3 power balance in numbers (no CasADi): its drag factor and resistance, the
speed a power holds on a grade (`steady_speed_mps`, for guesses and checks) and an upper
bound on the speed of any physical ride of a course (`speed_bound_mps`, a simple bound of
the OCPs). The symbolic E3 is `model.dynamics`; these are its numeric twins.
"""

from __future__ import annotations

import math
from typing import Any

from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.rider import Rider


def drag_factor_kgpm(rider: Rider, conditions: Conditions) -> float:
    """`k_v = rho CdA / 2` (kg/m): the air drag of E3 is `k_v v_air |v_air|`."""
    return 0.5 * conditions.air_density_kgpm3 * rider.drag_area_m2


def resistance_n(v: Any, sin_b: Any, cos_b: Any, rider: Rider, k_v: float) -> Any:
    """Rolling, gravity and air resistance (N) at speed `v` in still air (E3); numbers or
    arrays alike (`sin_b`, `cos_b`: of the slope angle; `k_v`: `drag_factor_kgpm`)."""
    return rider.mass_kg * GRAVITY_MPS2 * (rider.crr * cos_b + sin_b) + k_v * v * v


def steady_speed_mps(power_w: float, rider: Rider, conditions: Conditions = Conditions(),
                     grade: float = 0.0) -> float:
    """Steady speed of the E3 power balance (Martin et al. 1998 form, no wind), m/s.

    Solves `eta P = v (m g (c_rr cos b + sin b) + k_v v^2)` (`eta`: drivetrain efficiency)
    for the physical root: the largest real root of the depressed cubic
    `v^3 + a v + b = 0`. Climbing or on the flat (`a > 0`) there is one real root
    (Cardano). On a descent steep enough that gravity beats rolling resistance (`a < 0`)
    the cubic can have three real roots (0 < v1 < v2 with a negative third when P is small,
    a double root at P = 0 ... ); the physical speed is where propulsion plus gravity
    balances drag from above, the largest root, from the trigonometric form. With P = 0
    that is the terminal speed `sqrt(-a)`. One Newton step polishes the closed form
    (Cardano loses digits when `a` is large and `b` small). Returns 0 when there is no
    positive balance (no power on a road that does not descend: the rider stops).

    Raises:
        ValueError: negative or non-finite power, or a non-finite grade.
    """
    if not (math.isfinite(power_w) and power_w >= 0 and math.isfinite(grade)):
        raise ValueError(f"steady speed needs a power >= 0 W and a finite grade, got "
                         f"{power_w!r} W at {grade!r}")
    beta = math.atan(grade)
    k_v = drag_factor_kgpm(rider, conditions)
    a = rider.mass_kg * GRAVITY_MPS2 * (rider.crr * math.cos(beta) + math.sin(beta)) / k_v
    b = -rider.drivetrain_efficiency * power_w / k_v
    disc = (b / 2) ** 2 + (a / 3) ** 3
    if disc >= 0:  # one real root
        root = math.sqrt(disc)
        v = math.copysign(abs(-b / 2 + root) ** (1 / 3), -b / 2 + root) + math.copysign(
            abs(-b / 2 - root) ** (1 / 3), -b / 2 - root)
    else:  # three real roots (a < 0): the largest, trigonometric form
        r = math.sqrt(-a / 3)
        cos3 = max(-1.0, min(1.0, (3 * b / (2 * a)) * math.sqrt(-3 / a)))
        v = 2 * r * math.cos(math.acos(cos3) / 3)
    slope = 3 * v * v + a
    if slope > 0:  # Newton polish; f is convex beyond its largest root's neighbourhood
        v -= (v ** 3 + a * v + b) / slope
    return max(v, 0.0)


def speed_bound_mps(rider: Rider, conditions: Conditions, steepest_grade: float,
                    *, start_mps: float = 0.0) -> float:
    """An upper bound on the speed of any physical ride of the course (m/s).

    Above the steady speed at full power (`max_power_w`) on the steepest descent the
    rider decelerates everywhere on the course, so no ride that starts slower can get
    faster; a tail wind adds at most its own speed. The margin (x1.25 + 3 m/s) keeps
    the bound inactive at every physical optimum; it exists so that an integration
    artefact (a coarse step at low speed, issue 18) can never be an optimum.
    """
    grade = min(float(steepest_grade), 0.0)
    v_max = steady_speed_mps(rider.max_power_w, rider, conditions, grade)
    return max(1.25 * (v_max + conditions.wind_speed_mps) + 3.0, start_mps)
