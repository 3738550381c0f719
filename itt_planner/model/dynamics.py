"""The rider-bicycle dynamics in the spatial domain as CasADi expressions (model.md 2-6).

Two models share one parameter vector and one interface:

- the 3D model, states `x = [n, alpha, phi, phi_dot, v, W_n, delta_n, E_n]`, controls
  `u = [u_delta, u_W]` (E1-E9, C15, C16);
- the 1D model (model.md section 6), states `x = [v, W_n, E_n]`, control `u = [u_W]`;
- the 1D model on a fixed line that knows the line's corners (`build_1d_line`): the
  same states, with C15 and C16 at the lateral acceleration `v^2 kappa` of the line;
- the steady-lean 3D model of the receding horizon (`build_3d_steady_lean`): roll
  E4-E5 at equilibrium, states `x = [n, alpha, v, W_n, delta_n, E_n]` (why: `ocp.horizon`).

Everything rider- or weather-specific (mass, drag, grip, wind, ...) is a symbolic
parameter (`params.ModelParams.vector()`), not a constant, so the compiled integrator of
the OCPs is reused for every rider and condition. The road enters through four numbers
per interval (`params.ROAD`): the mean curvature and slope, the heading for the wind
projection (E3), and the interval length; the path constraints take it too (the 1D
model on a line reads its curvature there). `rk4_step` integrates one interval. The 3D
models ride E3 on the slope of their own path, not the centre line's (`path_slope_rad`,
a [fix] of model.md's E3: the road is level across its width, so a line inside a bend
is steeper than the centre line, one outside it flatter).

Non-smooth terms of the physics (`max(W_n, 0)`, `|v - V_w|`, the E9 switch at critical
power) are smoothed with small, documented widths so a Newton-type solver sees C1
functions; the numeric `power_w` reported in a Plan uses the exact formula.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import casadi as ca
import numpy as np

from itt_planner.model.conditions import GRAVITY_MPS2
from itt_planner.model.params import PARAMS, ROAD
from itt_planner.model.wprime import WPrimeModel, e_n_rate

#: State names of the 3D model (model.md section 2), in vector order.
STATES_3D = ("n", "alpha", "phi", "phi_dot", "v", "w_n", "delta_n", "e_n")
CONTROLS_3D = ("u_delta", "u_w")
STATES_1D = ("v", "w_n", "e_n")
CONTROLS_1D = ("u_w",)
#: The full-course models by name (`build_model`); "1dline" is the 1D on a fixed line
#: (`build_1d_line`), solved on a line's course (`ocp.line_plan`).
MODELS = ("3d", "1d", "1dline")

#: Smoothing width of max(W_n, 0) in the dynamics (normalised power; 1e-3 is ~1 W).
_EPS_WN = 1e-3
#: Smoothing of |v - V_w| (m/s)^2 under the square root.
_EPS_AIR = 1e-2
#: Softplus width of the E9 switch at critical power (W); part of the model (verify.py).
E9_SHARPNESS_W = 5.0
#: Speed floor inside divisions (m/s), below the OCP's v_min so never active at a solution.
_V_GUARD_MPS = 0.2
#: Width (normalised) of the smooth pedalling gate of C15.
_EPS_PEDAL = 0.02
#: C15 switches pedalling off slightly before `pedal_lean` so that the smoothed gate
#: leaves only a watt or two at exactly `pedal_lean`.
_PEDAL_MARGIN = 0.95


@dataclass(frozen=True)
class SpatialModel:
    """One model as CasADi Functions of `(x, u, road, par)` (all SX inside).

    Attributes:
        name: "3d", "3dsteady", "1d" or "1dline".
        states, controls: names, in vector order.
        ode: `(x, u, road, par) -> (dx/ds, dt/ds, dJ/ds)`.
        path: `(x, road, par) -> g` path constraints that must be <= 0 (C16 - 1, C15);
            `road` is that of the interval the node starts (the last node: the last
            interval's). Only the 1D model on a line reads it (its curvature).
        outputs: `(x, par) -> [power_w, ax, ay, friction_use]` for reporting, or
            `(x, road, par) -> ...` where the outputs depend on the road (`build_1d_line`:
            a_y = v^2 kappa; `outputs.n_in()` says which).
    """

    name: str
    states: tuple[str, ...]
    controls: tuple[str, ...]
    ode: ca.Function
    path: ca.Function
    outputs: ca.Function

    @property
    def nx(self) -> int:
        return len(self.states)

    @property
    def nu(self) -> int:
        return len(self.controls)

    def index(self, state: str) -> int:
        return self.states.index(state)


def _smooth_pos(a: ca.SX, eps: float) -> ca.SX:
    """C-infinity approximation of max(a, 0), error <= eps/2 at a = 0."""
    return 0.5 * (a + ca.sqrt(a * a + eps * eps))


def _par(p: ca.SX) -> dict[str, ca.SX]:
    return {name: p[i] for i, name in enumerate(PARAMS)}


def _longitudinal(v: ca.SX, w_n: ca.SX, e_n: ca.SX, psi: ca.SX, beta: ca.SX,
                  q: dict[str, ca.SX], wprime_model: WPrimeModel, eps_wn: float = _EPS_WN,
                  sharpness_w: float = E9_SHARPNESS_W) -> tuple[ca.SX, ca.SX]:
    """dv/dt (E3) and dE_n/dt (E9), shared by all models (smoothing widths: module doc).

    `beta` is the slope of the rider's own path (`path_slope_rad`; the road's on the
    centre line and for the 1D model), `psi` the absolute heading.
    """
    g = GRAVITY_MPS2
    # Guards for wild trial points only (inside the bounds they are inactive): speed in
    # divisions, and the E9 softplus argument that would overflow exp() far beyond W_max.
    v = ca.fmax(v, _V_GUARD_MPS)
    p_plus = q["p_max"] * _smooth_pos(w_n, eps_wn)  # crank power: E9 and the advice
    p_brake = q["mu_x"] * g * q["mass"] * v * (w_n - _smooth_pos(w_n, eps_wn))
    # E3 [fix]: wind projected on the absolute heading psi; tail wind positive.
    v_wind = q["wind_e"] * ca.cos(psi) + q["wind_n"] * ca.sin(psi)
    v_air = v - v_wind
    drag = q["k_v"] * v_air * ca.sqrt(v_air * v_air + _EPS_AIR)
    # E3 [fix]: gravity and rolling on the slope of the path ridden (`path_slope_rad`).
    resist = q["mass"] * g * (q["crr"] * ca.cos(beta) + ca.sin(beta))
    # E3 with the drivetrain losses: power at the wheel = efficiency x crank power.
    v_dot = ((q["efficiency"] * p_plus + p_brake) / (q["mass"] * v) - resist / q["mass"]
             - drag / q["mass"])
    e_dot = e_n_rate(e_n, ca.fmin(p_plus, 2 * q["p_max"]), q["cp"], q["w_prime"], wprime_model,
                     sharpness_w=sharpness_w)
    return v_dot, e_dot


def _ax_squared(v: ca.SX, w_n: ca.SX, q: dict[str, ca.SX]) -> ca.SX:
    """(a_x / (mu_x g))^2 of C16: tyre force per unit mass, pedalling or braking.

    max(W_n,0)^2 and min(W_n,0)^2 are C1, so no smoothing is needed here.
    """
    g = GRAVITY_MPS2
    pedal = q["efficiency"] * q["p_max"] * ca.fmax(w_n, 0) / (q["mass"] * v) / (q["mu_x"] * g)
    brake = ca.fmin(w_n, 0)
    return pedal * pedal + brake * brake


def _kinematics(n: ca.SX, alpha: ca.SX, v: ca.SX, delta_n: ca.SX, kappa: ca.SX,
                q: dict[str, ca.SX]) -> tuple[ca.SX, ca.SX]:
    """Progress rate `s_dot` (E8) and yaw rate (E1), shared by both 3D models."""
    delta = delta_n * q["steer_max"]
    s_dot = ca.fmax(v, _V_GUARD_MPS) * ca.cos(alpha) / (1 - n * kappa)  # E8
    yaw_rate = v * ca.tan(delta) / q["wheelbase"]  # E1 [fix]: kinematic bicycle v tan(d)/L
    return s_dot, yaw_rate


def path_slope_rad(beta: Any, n: Any, alpha: Any, kappa: Any) -> Any:
    """Slope angle of the rider's own path (E3 [fix]): `tan(beta_path) = tan(beta)
    cos(alpha) / (1 - n kappa)`; CasADi expressions or NumPy numbers/arrays alike.

    Why: the road is level across its width (model.md section 1: the altitude `z(s)` is a
    function of the centre line's arc length only), so a rider at offset `n` heading
    `alpha` off the road climbs `dz/dt = tan(beta) s_dot = v tan(beta) cos(alpha) /
    (1 - n kappa)` (E8), while travelling `v` along the path: the grade of the path is
    `(dz/dt) / v`. On the centre line (`n = alpha = 0`) it is the road's `beta`; inside
    a bend (`n kappa > 0`) the path is shorter and steeper, outside flatter, and an
    angled line (`alpha != 0`) flatter. With `beta` in E3 instead, a line inside a bend
    on a climb climbed less than the road rises (issue 18: worth ~0.6 % on Tokyo 2020).
    The 1D model on a line course (`course.racing_line.offset_course`) has the same
    slope: the altitude over the line's own length.
    """
    if any(isinstance(a, (ca.SX, ca.MX, ca.DM)) for a in (beta, n, alpha, kappa)):
        return ca.atan(ca.tan(beta) * ca.cos(alpha) / (1 - n * kappa))
    return np.arctan(np.tan(beta) * np.cos(alpha) / (1 - np.asarray(n) * kappa))


def _command_rate(u: ca.SX, rate_max: ca.SX, full_scale: ca.SX) -> ca.SX:
    """E6/E7 [fix]: d(normalised command)/dt from a control normalised by its max rate."""
    return u * rate_max / full_scale


def _spatial_ode(name: str, x: ca.SX, u: ca.SX, road: ca.SX, p: ca.SX, x_dot: ca.SX,
                 s_dot: ca.SX, penalties: tuple[ca.SX, ...]) -> ca.Function:
    """Time derivatives -> space derivatives (divide by `s_dot`), with dt/ds and the
    running cost of the objective (section 5): dt/ds (1 + w_1 u_delta^2 + w_2 u_W^2)."""
    dt_ds = 1 / s_dot
    weight: Any = 1
    for term in penalties:  # summed left to right, as the objective is written
        weight = weight + term
    return ca.Function(name, [x, u, road, p], [x_dot * dt_ds, dt_ds, dt_ds * weight],
                       ["x", "u", "road", "p"], ["dxds", "dtds", "dJds"])


def _friction(v: ca.SX, w_n: ca.SX, ay: ca.SX, q: dict[str, ca.SX]) -> ca.SX:
    """C16: the friction ellipse on the tyre forces."""
    return _ax_squared(v, w_n, q) + (ay / (q["mu_y"] * GRAVITY_MPS2)) ** 2


def _pedal_gate(w_n: ca.SX, phi: ca.SX, q: dict[str, ca.SX]) -> ca.SX:
    """C15: `W_n <= max(0, 1 - (phi/phi_pedal)^2)` as `g <= 0`, smoothed from the
    feasible side (`_PEDAL_MARGIN`, `_EPS_PEDAL`)."""
    r = phi / (_PEDAL_MARGIN * q["pedal_lean"])
    return w_n - _smooth_pos(1 - r * r, _EPS_PEDAL)


def build_3d(wprime_model: WPrimeModel = WPrimeModel.SKIBA) -> SpatialModel:
    """The 3D model, E1-E9 with the [fix]es of model.md, path constraints C15 and C16."""
    x = ca.SX.sym("x", len(STATES_3D))
    u = ca.SX.sym("u", len(CONTROLS_3D))
    road = ca.SX.sym("road", len(ROAD))
    p = ca.SX.sym("p", len(PARAMS))
    n, alpha, phi, phi_dot, v, w_n, delta_n, e_n = (x[i] for i in range(8))
    u_delta, u_w = u[0], u[1]
    kappa, beta, theta = road[0], road[1], road[2]
    q = _par(p)
    g = GRAVITY_MPS2

    s_dot, yaw_rate = _kinematics(n, alpha, v, delta_n, kappa, q)
    i_x0 = q["roll_inertia"] + q["com_height"] ** 2 * q["mass"]
    # E5 [fix]: nonlinear inverted pendulum, steady lean tan(phi) = -(v^2 tan(d)/L)/g.
    phi_ddot = (q["com_height"] * q["mass"] / i_x0) * (
        g * ca.sin(phi) + v * yaw_rate * ca.cos(phi))
    v_dot, e_dot = _longitudinal(v, w_n, e_n, theta + alpha,
                                 path_slope_rad(beta, n, alpha, kappa), q, wprime_model)
    x_dot = ca.vertcat(
        v * ca.sin(alpha),  # E2 (time derivative)
        yaw_rate - kappa * s_dot,  # E1
        phi_dot,  # E4
        phi_ddot,  # E5
        v_dot,  # E3
        _command_rate(u_w, q["power_rate_max"], q["p_max"]),  # E6
        _command_rate(u_delta, q["steer_rate_max"], q["steer_max"]),  # E7
        e_dot,  # E9
    )
    ode = _spatial_ode(f"ode3d_{wprime_model.value}", x, u, road, p, x_dot, s_dot,
                       (q["w_delta"] * u_delta ** 2, q["w_power"] * u_w ** 2))

    ay = v * yaw_rate
    friction = _friction(v, w_n, ay, q)
    path = ca.Function("path3d", [x, road, p],
                       [ca.vertcat(friction - 1, _pedal_gate(w_n, phi, q))],
                       ["x", "road", "p"], ["g"])
    outputs = ca.Function("out3d", [x, p], [_report(v, w_n, ay, friction, q)], ["x", "p"], ["y"])
    return SpatialModel("3d", STATES_3D, CONTROLS_3D, ode, path, outputs)


#: State names of the steady-lean horizon model (`build_3d_steady_lean`), in vector order.
STATES_3D_STEADY = ("n", "alpha", "v", "w_n", "delta_n", "e_n")


def steady_lean_rad(ay: ca.SX | np.ndarray) -> ca.SX | np.ndarray:
    """Lean of the steady turn (E5 with phi_ddot = phi_dot = 0): tan(phi) = -a_y / g."""
    if isinstance(ay, (ca.SX, ca.MX, ca.DM)):
        return -ca.atan(ay / GRAVITY_MPS2)
    return -np.arctan(np.asarray(ay) / GRAVITY_MPS2)


def build_3d_steady_lean(wprime_model: WPrimeModel = WPrimeModel.SKIBA, *,
                         eps_wn: float = _EPS_WN, sharpness_w: float = E9_SHARPNESS_W
                         ) -> SpatialModel:
    """The 3D model with quasi-steady roll, for the receding horizon (not the full plan).

    Same as `build_3d` (E1-E3, E6-E9, C15, C16) except that the roll dynamics E4-E5 are
    replaced by their equilibrium, the steady turn `tan(phi) = -a_y / g` with
    `a_y = v^2 tan(delta) / L`: `phi` and `phi_dot` stop being states and `phi` is an
    algebraic function of speed and steering. This removes the unstable roll mode
    (time constant ~0.45 s), so shooting intervals of 5-15 m are well conditioned.
    Lean and grip stay linked: C16 bounds `a_y`, hence `phi`, and C15 gates pedalling
    on that `phi`. States `x = [n, alpha, v, W_n, delta_n, E_n]`, controls as the 3D model.
    """
    x = ca.SX.sym("x", len(STATES_3D_STEADY))
    u = ca.SX.sym("u", len(CONTROLS_3D))
    road = ca.SX.sym("road", len(ROAD))
    p = ca.SX.sym("p", len(PARAMS))
    n, alpha, v, w_n, delta_n, e_n = (x[i] for i in range(6))
    u_delta, u_w = u[0], u[1]
    kappa, beta, theta = road[0], road[1], road[2]
    q = _par(p)

    s_dot, yaw_rate = _kinematics(n, alpha, v, delta_n, kappa, q)
    v_dot, e_dot = _longitudinal(v, w_n, e_n, theta + alpha,
                                 path_slope_rad(beta, n, alpha, kappa), q, wprime_model,
                                 eps_wn, sharpness_w)
    x_dot = ca.vertcat(
        v * ca.sin(alpha),  # E2
        yaw_rate - kappa * s_dot,  # E1
        v_dot,  # E3
        _command_rate(u_w, q["power_rate_max"], q["p_max"]),  # E6
        _command_rate(u_delta, q["steer_rate_max"], q["steer_max"]),  # E7
        e_dot,  # E9
    )
    tag = f"{wprime_model.value}_{eps_wn:g}_{sharpness_w:g}".replace(".", "p").replace("-", "m")
    ode = _spatial_ode(f"ode3dsteady_{tag}", x, u, road, p, x_dot, s_dot,
                       (q["w_delta"] * u_delta ** 2, q["w_power"] * u_w ** 2))

    ay = v * yaw_rate
    friction = _friction(v, w_n, ay, q)
    pedal = _pedal_gate(w_n, cast(ca.SX, steady_lean_rad(ay)), q)  # C15 at the steady lean
    path = ca.Function("path3dsteady", [x, road, p], [ca.vertcat(friction - 1, pedal)],
                       ["x", "road", "p"], ["g"])
    outputs = ca.Function("out3dsteady", [x, p], [_report(v, w_n, ay, friction, q)],
                          ["x", "p"], ["y"])
    return SpatialModel("3dsteady", STATES_3D_STEADY, CONTROLS_3D, ode, path, outputs)


def build_1d(wprime_model: WPrimeModel = WPrimeModel.SKIBA) -> SpatialModel:
    """The 1D baseline (model.md section 6): E3, E6, E9 with n = alpha = phi = delta = 0."""
    return _build_1d(wprime_model, line=False)


def build_1d_line(wprime_model: WPrimeModel = WPrimeModel.SKIBA) -> SpatialModel:
    """The 1D model on a fixed line that knows its corners ("1dline"): a point mass held
    on a line's course (`racing_line.offset_course`), E3, E6, E9 as `build_1d`, with the
    lateral acceleration `a_y = v^2 kappa` (the road data's curvature: the line's) in
    C16 and C15 at the steady lean `steady_lean_rad(a_y)`, as `build_3d_steady_lean`.
    Why: the plain 1D ignores corners (model.md section 6); on the line of a 3D plan it
    took the Bologna hairpins at up to 3.8 g (bench/RESULTS.md, 2026-12-02)."""
    return _build_1d(wprime_model, line=True)


def _build_1d(wprime_model: WPrimeModel, *, line: bool) -> SpatialModel:
    """`build_1d` (`line` False) or `build_1d_line`: one ODE, their own path constraints."""
    name = "1dline" if line else "1d"
    x = ca.SX.sym("x", len(STATES_1D))
    u = ca.SX.sym("u", len(CONTROLS_1D))
    road = ca.SX.sym("road", len(ROAD))
    p = ca.SX.sym("p", len(PARAMS))
    v, w_n, e_n = x[0], x[1], x[2]
    q = _par(p)
    v_dot, e_dot = _longitudinal(v, w_n, e_n, road[2], road[1], q, wprime_model)
    x_dot = ca.vertcat(v_dot, _command_rate(u[0], q["power_rate_max"], q["p_max"]), e_dot)
    # The ODE's name keys the compiled kernels (`ocp.transcription`): one per model.
    ode = _spatial_ode(f"ode{name}_{wprime_model.value}", x, u, road, p, x_dot,
                       ca.fmax(v, _V_GUARD_MPS), (q["w_power"] * u[0] ** 2,))
    if not line:
        friction = _ax_squared(v, w_n, q)
        path = ca.Function("path1d", [x, road, p], [friction - 1], ["x", "road", "p"], ["g"])
        outputs = ca.Function("out1d", [x, p], [_report(v, w_n, 0 * v, friction, q)],
                              ["x", "p"], ["y"])
        return SpatialModel(name, STATES_1D, CONTROLS_1D, ode, path, outputs)
    ay = v * v * road[0]
    friction = _friction(v, w_n, ay, q)
    pedal = _pedal_gate(w_n, cast(ca.SX, steady_lean_rad(ay)), q)  # C15 at the steady lean
    path = ca.Function("path1dline", [x, road, p], [ca.vertcat(friction - 1, pedal)],
                       ["x", "road", "p"], ["g"])
    outputs = ca.Function("out1dline", [x, road, p], [_report(v, w_n, ay, friction, q)],
                          ["x", "road", "p"], ["y"])
    return SpatialModel(name, STATES_1D, CONTROLS_1D, ode, path, outputs)


def _report(v: ca.SX, w_n: ca.SX, ay: ca.SX, friction: ca.SX, q: dict[str, ca.SX]) -> ca.SX:
    """[power_w, ax, ay, friction_use] with the exact (unsmoothed) power of section 2.

    power_w is the rider's (crank) power when pedalling, the braking power at the contact
    point when negative; ax is the tyre force per unit mass (wheel power when pedalling).
    """
    g = GRAVITY_MPS2
    power = q["p_max"] * ca.fmax(w_n, 0) + q["mu_x"] * g * q["mass"] * v * ca.fmin(w_n, 0)
    ax = (q["efficiency"] * q["p_max"] * ca.fmax(w_n, 0) / (q["mass"] * v)
          + q["mu_x"] * g * ca.fmin(w_n, 0))
    return ca.vertcat(power, ax, ay, friction)


def build_model(kind: str, wprime_model: WPrimeModel = WPrimeModel.SKIBA) -> SpatialModel:
    """`build_3d`, `build_1d` or `build_1d_line` by name (`MODELS`).

    Raises:
        ValueError: unknown model name.
    """
    builders = {"3d": build_3d, "1d": build_1d, "1dline": build_1d_line}
    if kind not in builders:
        raise ValueError(f"unknown model {kind!r}: choose one of {', '.join(MODELS)}")
    return builders[kind](wprime_model)


def rk4_step(model: SpatialModel, substeps: int) -> ca.Function:
    """One multiple-shooting interval: `substeps` RK4 steps over `road[ds]` metres.

    Returns `F(x, u, road, p) -> (x_end, dt, dJ)` with the interval's time and cost as
    quadratures. Controls are constant over the interval (zero-order hold).
    """
    x = ca.SX.sym("x", model.nx)
    u = ca.SX.sym("u", model.nu)
    road = ca.SX.sym("road", len(ROAD))
    p = ca.SX.sym("p", len(PARAMS))
    h = road[3] / substeps
    xk = x
    t: Any = 0  # SX after the first step
    j: Any = 0
    for _ in range(substeps):
        k1, t1, j1 = model.ode(xk, u, road, p)
        k2, t2, j2 = model.ode(xk + h / 2 * k1, u, road, p)
        k3, t3, j3 = model.ode(xk + h / 2 * k2, u, road, p)
        k4, t4, j4 = model.ode(xk + h * k3, u, road, p)
        xk = xk + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        t = t + h / 6 * (t1 + 2 * t2 + 2 * t3 + t4)
        j = j + h / 6 * (j1 + 2 * j2 + 2 * j3 + j4)
    return ca.Function(f"F{model.name}_{substeps}", [x, u, road, p], [xk, t, j],
                       ["x", "u", "road", "p"], ["xf", "dt", "dJ"])
