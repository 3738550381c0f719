"""Initial guesses of the full-course OCP, valid for any rider on any grade, and the
speed-aware mesh caps that go with them (issue 14 item 2, issue 18).

- `speed_guess`: steady speed at critical power on the local grade (`model.steady.steady_speed_mps`,
  the physical root of the cubic on every branch: terminal speed on steep descents),
  capped by `_GUESS_GRIP` of the lateral limit in corners (grip or the rider's own,
  `model.params.lateral_limit_mps2`), with bounded acceleration and braking;
- `initial_guess`: that speed with steady lean and steering along the centre line;
- `plan_guess`: an existing plan moved onto another mesh (warm starts, mesh studies);
- `speed_spacing_cap` / `plan_spacing_cap`: the largest mesh step the guessed (or a
  plan's) speed allows (`mesh.speed_spacing_m`): `dv/ds = a/v` is stiff where slow.
"""

from __future__ import annotations

import math

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.errors import SolveError
from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.dynamics import CONTROLS_1D, STATES_1D, SpatialModel
from itt_planner.model.params import lateral_limit_mps2
from itt_planner.model.rider import Rider
from itt_planner.model.steady import steady_speed_mps
from itt_planner.ocp.bounds import V_MIN_MPS
from itt_planner.ocp.mesh import speed_spacing_m
from itt_planner.ocp.plan import Plan

#: Share of the grip the launch may use at the start node (model.md launch note).
LAUNCH_GRIP = 0.8
#: Share of the lateral limit the initial guess uses in corners.
_GUESS_GRIP = 0.7
#: The `Plan` array of each state and control of the spatial models.
PLAN_ARRAYS = {"n": "n_m", "alpha": "alpha_rad", "phi": "phi_rad", "phi_dot": "phi_dot_radps",
               "v": "v_mps", "w_n": "w_n", "delta_n": "delta_n", "e_n": "e_n",
               "u_delta": "u_delta", "u_w": "u_w"}


def speed_guess(course: Course, nodes: np.ndarray, rider: Rider, conditions: Conditions,
                v0: float, corners: bool) -> np.ndarray:
    """A speed profile to start from: steady speed at CP on the local grade, capped by
    `_GUESS_GRIP` of the lateral limit in corners, with bounded acceleration/deceleration.
    Finite and >= 2 m/s on any grade (the steady speed is the physical root of the cubic
    on every branch, issue 14)."""
    grade = np.tan(course.at("beta_rad", nodes))
    v = np.array([steady_speed_mps(rider.critical_power_w, rider, conditions, g) for g in grade])
    v = np.maximum(v, 2.0)
    if corners:
        kappa = np.abs(course.at("kappa_per_m", nodes)) + 1e-9
        v = np.minimum(v, np.sqrt(_GUESS_GRIP * lateral_limit_mps2(rider, conditions) / kappa))
    ds = np.diff(nodes)
    v[0] = v0
    for i in range(1, len(v)):  # accelerate at <= 1 m/s^2
        v[i] = min(v[i], math.sqrt(v[i - 1] ** 2 + 2 * 1.0 * ds[i - 1]))
    for i in range(len(v) - 2, 0, -1):  # brake at <= 3 m/s^2
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2 * 3.0 * ds[i]))
    speed: np.ndarray = v
    return speed


def initial_guess(model: SpatialModel, course: Course, nodes: np.ndarray, rider: Rider,
                  conditions: Conditions, v0: float) -> tuple[np.ndarray, np.ndarray]:
    """States (nx x N+1) and controls (nu x N) to start the NLP from."""
    v = speed_guess(course, nodes, rider, conditions, v0, corners=model.name == "3d")
    x = np.zeros((model.nx, len(nodes)))
    x[model.index("v")] = v
    x[model.index("w_n")] = rider.critical_power_w / rider.max_power_w
    x[model.index("e_n")] = 1.0 - 0.95 * (nodes - nodes[0]) / max(nodes[-1] - nodes[0], 1.0)
    if model.name == "3d":
        kappa = course.at("kappa_per_m", nodes)
        # Steady turn on the centre line: tan(delta) = L kappa, tan(phi) = -v^2 kappa / g (E5).
        x[model.index("delta_n")] = np.arctan(rider.wheelbase_m * kappa) / rider.steer_max_rad
        x[model.index("phi")] = -np.arctan(v ** 2 * kappa / GRAVITY_MPS2)
    return x, np.zeros((model.nu, len(nodes) - 1))


def plan_guess(model: SpatialModel, plan: Plan, nodes: np.ndarray, x: np.ndarray,
               u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An initial guess taken from an existing plan, moved onto `nodes`.

    States are interpolated linearly in s. A plan's controls hold over its intervals
    (`course_nlp.to_plan`), so each new interval takes the control of the plan interval that holds
    its midpoint. Rows a 1D plan does not have (the lateral states and `u_delta` of the
    3D model) keep the values of `x`, `u` (the default guess); the caller clips the
    result to the bounds and keeps its own initial state. (Integrating the plan's own
    dynamics between its nodes instead of interpolating cut the initial continuity gaps
    of the roll states 4-20x but not the iterations: 276 vs 286 on a uniform 2 m mesh
    of verona-like, so the simpler interpolation stays.)

    Raises:
        SolveError: status "invalid_input": the plan does not span the mesh (another
            course, or a plan of the rest of the course for a mesh from before its start).
    """
    if plan.s_m[0] - nodes[0] > 1.0 or abs(plan.s_m[-1] - nodes[-1]) > 1.0:
        msg = (f"the guess spans {plan.s_m[0]:.0f}-{plan.s_m[-1]:.0f} m, the mesh "
               f"{nodes[0]:.0f}-{nodes[-1]:.0f} m: a plan of another course?")
        raise SolveError(msg, status="invalid_input")
    has = set(STATES_1D + CONTROLS_1D) if plan.model == "1d" else set(PLAN_ARRAYS)
    x, u = x.copy(), u.copy()
    for i, name in enumerate(model.states):
        if name in has:
            x[i] = plan.at(PLAN_ARRAYS[name], nodes)
    mid = 0.5 * (nodes[1:] + nodes[:-1])
    held = np.clip(np.searchsorted(plan.s_m, mid, side="right") - 1, 0, plan.n_nodes - 1)
    for i, name in enumerate(model.controls):
        if name in has:
            u[i] = getattr(plan, PLAN_ARRAYS[name])[held]
    return x, u


def speed_spacing_cap(course: Course, rider: Rider, conditions: Conditions, model: str,
               start_m: float, v0: float) -> np.ndarray:
    """A-priori spacing cap on the course grid from the guessed speed (mesh module doc).

    The launch: the speed a tyre force of `LAUNCH_GRIP` of the grip could reach, at
    the tyre force of critical power; elsewhere the guess (`speed_guess`) at CP.
    """
    grid = course.s_m
    ahead = np.maximum(grid - start_m, 0.0)
    v = speed_guess(course, np.maximum(grid, start_m), rider, conditions, v0,
                    corners=model == "3d")
    grip = LAUNCH_GRIP * conditions.mu_x * GRAVITY_MPS2
    v = np.minimum(v, np.sqrt(v0 ** 2 + 2 * grip * ahead))
    accel = np.minimum(rider.drivetrain_efficiency * rider.critical_power_w
                       / (rider.mass_kg * np.maximum(v, V_MIN_MPS)), grip)
    return speed_spacing_m(v, accel)


def plan_spacing_cap(course: Course, plan: Plan, rider: Rider, conditions: Conditions
                     ) -> np.ndarray:
    """Spacing cap on the course grid from a plan's own speeds and tyre forces
    (`mesh.speed_spacing_m`): where the rider of `plan` is slow, finer."""
    v = np.maximum(plan.at("v_mps", course.s_m), V_MIN_MPS)
    a_brake = conditions.mu_x * GRAVITY_MPS2 * np.abs(np.minimum(plan.at("w_n", course.s_m), 0))
    a_pedal = np.abs(plan.at("power_w", course.s_m)) / (rider.mass_kg * v)
    return speed_spacing_m(v, np.maximum(a_brake, a_pedal))
