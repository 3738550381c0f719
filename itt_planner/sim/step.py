"""One time step of the virtual rider: the 3D model (E1-E9) in the time domain under the
rider's lean, steering, power and braking controller, as a compiled CasADi function."""

from __future__ import annotations

import casadi as ca

from itt_planner.course.geometry import Course
from itt_planner.model.conditions import GRAVITY_MPS2
from itt_planner.model.dynamics import SpatialModel, build_3d
from itt_planner.model.params import PARAMS
from itt_planner.sim.behaviour import RiderBehaviour

#: State and reference layout of `_closed_loop_step`.
_REFS = ("n_ref", "dn_ref_ds", "w_cmd", "v_brake", "kappa_preview")


def _closed_loop_step(behaviour: RiderBehaviour, substeps: int) -> ca.Function:
    """One time step of the 3D model (E1-E9 via `model.build_3d`) under the rider's
    controller: `(x, s, road, p, ref, dt) -> (x_next, s_next)`.

    Time domain: `dx/dt = (dx/ds) / (dt/ds)` and `ds/dt = 1 / (dt/ds)` (E8).
    Lateral control, a cascade any rider does without thinking: the reference line's
    curvature a moment ahead (feed-forward) and the heading error to the line set a
    desired yaw rate; the steady lean of that turn,
    `tan(phi) = -v r / g` (E5), is the desired lean; steering is chosen so the roll
    dynamics E5 follow it with a critically damped response (feedback linearisation of
    E5 for the yaw rate, then `delta = atan(r L / v)`). Steering is imposed directly
    (its rate is unbounded in the model, C14 bounds its angle). Grip (C16) is a hard
    limit of the truth: the desired turn is capped at `grip_lateral mu_y g`, the
    steering at `|a_y| <= mu_y g`, and the longitudinal tyre force (pedalling or
    braking) gets only what the ellipse leaves, so the friction use never exceeds 1; a
    rider who is too fast runs wide. Power: the target (normalised `W_n`) with a
    first-order lag, braking when faster than the advised speed or than the grip
    envelope ahead (`Reference.at`), no pedalling at high lean (C15), and at most CP
    when W' is exhausted.
    """
    b = behaviour
    model = build_3d()
    x = ca.SX.sym("x", model.nx)
    s = ca.SX.sym("s")
    road = ca.SX.sym("road", 4)
    p = ca.SX.sym("p", len(PARAMS))
    ref = ca.SX.sym("ref", len(_REFS))
    dt = ca.SX.sym("dt")
    q = {name: p[i] for i, name in enumerate(PARAMS)}
    refs = tuple(ref[i] for i in range(len(_REFS)))
    i_delta = model.index("delta_n")

    def controlled(xk: ca.SX) -> tuple[ca.SX, ca.SX]:
        return _controlled(xk, road, q, refs, b, model)

    def deriv(xk: ca.SX) -> tuple[ca.SX, ca.SX]:
        x_ctrl, u = controlled(xk)
        dxds, dtds, _ = model.ode(x_ctrl, u, road, p)
        xdot = dxds / dtds
        xdot[i_delta] = 0  # steering is imposed, not integrated
        return xdot, 1 / dtds

    h = dt / substeps
    xk, sk = x, s
    for _ in range(substeps):
        k1, s1 = deriv(xk)
        k2, s2 = deriv(xk + h / 2 * k1)
        k3, s3 = deriv(xk + h / 2 * k2)
        k4, s4 = deriv(xk + h * k3)
        xk = xk + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        sk = sk + h / 6 * (s1 + 2 * s2 + 2 * s3 + s4)
    x_final, _ = controlled(xk)  # report the steering actually applied
    outputs = model.outputs(x_final, p)
    return ca.Function("closed_loop_step", [x, s, road, p, ref, dt],
                       [x_final, sk, outputs], ["x", "s", "road", "p", "ref", "dt"],
                       ["x_next", "s_next", "y"])



def _controlled(xk: ca.SX, road: ca.SX, q: dict[str, ca.SX], refs: tuple[ca.SX, ...],
                b: RiderBehaviour, model: SpatialModel) -> tuple[ca.SX, ca.SX]:
    """The state with the rider's steering and power applied, and the power-rate input
    `(0, u_w)`, at state `xk` (see `_closed_loop_step`)."""
    g = GRAVITY_MPS2
    n_ref, dn_ref_ds, w_target, v_brake, kappa_ff = refs
    i_delta, i_w = model.index("delta_n"), model.index("w_n")
    n, alpha, phi, phi_dot, v, w_n, _, e_n = (xk[i] for i in range(model.nx))
    kappa = road[0]
    one_nk = 1 - n * kappa
    alpha_ref = ca.atan(dn_ref_ds * one_nk)
    # The lateral loop must stay well slower than the heading loop: its gain in
    # 1/s is `k_lateral_ps` whatever the speed (dn/dt = v alpha).
    err_n = ca.fmin(ca.fmax(b.k_lateral_ps * (n - n_ref) / ca.fmax(v, 3.0), -0.3), 0.3)
    # Feed-forward on the curvature of the LINE followed, a moment ahead (leaning in
    # takes time): a line that cuts a hairpin turns unlike the road; steering by the
    # road's curvature left the rider 2-5 m off the line there (bench/RESULTS.md).
    yaw_des = kappa_ff * v + b.k_heading_ps * (alpha_ref - err_n - alpha)
    # Grip (C16): the rider never asks for a turn tighter than the tyres carry, and
    # keeps headroom below it for the roll loop's steering transients.
    v_safe = ca.fmax(v, 0.5)
    ay_max = q["mu_y"] * g
    yaw_lim = b.grip_lateral * ay_max / v_safe
    yaw_des = ca.fmin(ca.fmax(yaw_des, -yaw_lim), yaw_lim)
    phi_des = -ca.atan(v * yaw_des / g)
    omega = b.roll_omega_radps
    phi_ddot_des = -omega ** 2 * (phi - phi_des) - 2 * omega * phi_dot
    i_x0 = q["roll_inertia"] + q["com_height"] ** 2 * q["mass"]
    c = q["com_height"] * q["mass"] / i_x0
    yaw_cmd = (phi_ddot_des / c - g * ca.sin(phi)) / (v_safe * ca.cos(phi))
    # Tyre limit on the steering itself: |a_y| = v^2 tan(delta) / L <= mu_y g. A
    # rider who would need more runs wide (n grows), as on a real road.
    tan_max = ay_max * q["wheelbase"] / (v_safe * v_safe)
    tan_delta = ca.fmin(ca.fmax(yaw_cmd * q["wheelbase"] / v_safe, -tan_max), tan_max)
    delta = ca.fmin(ca.fmax(ca.atan(tan_delta), -q["steer_max"]), q["steer_max"])
    # An exhausted rider cannot hold more than CP: the cap acts on the delivered
    # power at once (not through the lag), so W' cannot be overdrawn.
    cap = (q["cp"] - 10.0) / q["p_max"]  # below CP (the E9 switch is smoothed ~5 W)
    w_applied = ca.if_else(e_n < b.w_reserve, ca.fmin(w_n, cap), w_n)
    # Braking is a hand on the lever, not the legs: it acts at once (no power lag),
    # so the rider slows to the envelope without overshooting it.
    over = v - v_brake - b.brake_margin_mps
    w_applied = ca.if_else(over > 0, ca.fmin(w_applied, ca.fmax(-b.brake_gain * over, -1)),
                           w_applied)
    # Friction ellipse C16 with the lateral force first (the line is held): the
    # tyre force along the road, pedalling or braking, gets what grip is left.
    ay_use = v * v * ca.tan(delta) / q["wheelbase"] / ay_max
    ax_room = ca.sqrt(ca.fmax(1 - ay_use * ay_use, 0))
    pedal_max = ax_room * q["mu_x"] * g * q["mass"] * ca.fmax(v, 0) / q["p_max"]
    w_applied = ca.fmin(ca.fmax(w_applied, -ax_room), pedal_max)
    x_ctrl = ca.vertcat(xk[:i_w], w_applied, xk[i_w + 1:i_delta], delta / q["steer_max"],
                        xk[i_delta + 1:])
    # Pedalling command (braking is applied above): the legs stop while braking.
    w_cmd = ca.if_else(over > 0, ca.fmin(w_target, 0), w_target)
    w_cmd = ca.fmax(w_cmd, -1)
    gate = ca.fmax(0, 1 - (phi / q["pedal_lean"]) ** 2)  # C15
    w_cmd = ca.fmin(w_cmd, gate)
    w_cmd = ca.if_else(e_n < b.w_reserve, ca.fmin(w_cmd, cap), w_cmd)
    u_w = (w_cmd - w_n) / b.power_lag_s * q["p_max"] / q["power_rate_max"]
    return x_ctrl, ca.vertcat(0, u_w)

_STEPS: dict[RiderBehaviour, ca.Function] = {}


def step_function(behaviour: RiderBehaviour) -> ca.Function:
    """The compiled closed-loop step (built once per behaviour)."""
    if behaviour not in _STEPS:
        _STEPS[behaviour] = _closed_loop_step(behaviour, substeps=5)
    return _STEPS[behaviour]


def road_vector(course: Course, s: float) -> list[float]:
    """The `model.ROAD` vector at `s`: curvature, slope, heading (ds unused in time)."""
    return [float(course.at("kappa_per_m", s)), float(course.at("beta_rad", s)),
            float(course.at("theta_rad", s)), 1.0]
