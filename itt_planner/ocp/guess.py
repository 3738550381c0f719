"""Initial guesses of the full-course OCP, valid for any rider on any grade, and the
speed-aware mesh caps that go with them (issue 14 item 2, issue 18).

- `speed_guess`: steady speed at critical power on the local grade (`model.steady.steady_speed_mps`,
  the physical root of the cubic on every branch: terminal speed on steep descents),
  capped by `_GUESS_GRIP` of the lateral limit in corners (grip or the rider's own,
  `model.params.lateral_limit_mps2`), with bounded acceleration and braking;
- `initial_guess`: 1D, that speed; 3D, a quasi-steady ride (`arc_guess`) on a
  least-curvature line (`_line`) whose speed, power, lean and W' agree with each other
  and with C15/C16 (active arcs in place);
- `plan_guess`: an existing plan moved onto another mesh (warm starts, mesh studies);
- `speed_spacing_cap` / `plan_spacing_cap`: the largest mesh step the guessed (or a
  plan's) speed allows (`mesh.speed_spacing_m`): `dv/ds = a/v` is stiff where slow.
"""

from __future__ import annotations

import logging
import math
from dataclasses import replace
from typing import Any

import casadi as ca
import numpy as np
import scipy.sparse as sp

from itt_planner.course.geometry import Course
from itt_planner.course.racing_line import offset_heading_rad, offset_stretch
from itt_planner.errors import SolveError
from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.dynamics import CONTROLS_1D, STATES_1D, SpatialModel, path_slope_rad
from itt_planner.model.params import lateral_limit_mps2
from itt_planner.model.rider import Rider
from itt_planner.model.steady import drag_factor_kgpm, resistance_n, steady_speed_mps
from itt_planner.model.wprime import e_n_rate
from itt_planner.ocp.bounds import U_DELTA_MAX, U_W_MAX, V_MIN_MPS
from itt_planner.ocp.mesh import speed_spacing_m
from itt_planner.ocp.plan import Plan

log = logging.getLogger(__name__)

#: Share of the grip the launch may use at the start node (model.md launch note).
LAUNCH_GRIP = 0.8
#: Share of the lateral limit the initial guess uses in corners.
_GUESS_GRIP = 0.7
#: Share of the lateral limit the 3D guess corners at on the centre line, and of the
#: longitudinal grip (what the lateral force leaves of it, C16) it brakes with. The
#: optimum's line is wider than the centre line, so the full limit is still below its
#: corner speeds; at 0.85 the hairpin course (paper rider) ended in another local
#: optimum (183.88 s against 183.59 s).
_ARC_GRIP = 1.0
_ARC_BRAKE = 0.8
#: The 3D guess's line keeps this far from the road edges (`OcpSettings.margin_m`'s
#: default; the NLP clips the guess into its own bounds). With 1 m instead the hairpin
#: test course's plan was another local optimum: 25.17 s against 25.09 s (2026-12-02).
_LINE_MARGIN_M = 0.5
#: Weight (relative to the curvature term) that keeps the line's straight stretches
#: from drifting (the curvature alone leaves n linear there).
_LINE_REG = 1e-6
#: OSQP (through CasADi) on the line's QP: tolerances far below a millimetre, and the
#: polishing step that returns the exact solution of the active set it finds.
_LINE_QP_OPTIONS: dict[str, Any] = {"error_on_fail": False, "osqp": {
    "verbose": False, "polish": True, "eps_abs": 1e-7, "eps_rel": 1e-7, "max_iter": 20000}}
#: Integration step (m) of the 3D guess's forward ride.
_ARC_STEP_M = 1.0
#: Lowest E_n the 3D guess's pacing leaves (C12 pushes the guess off 0 anyway), and
#: the bisection steps on its pacing power.
_ARC_E_MIN = 0.02
_ARC_BISECTIONS = 10
#: C15's pedalling lean with the model's margin (`dynamics._PEDAL_MARGIN`).
_PEDAL_LEAN_SHARE = 0.95
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
    if model.name == "3d":
        return arc_guess(model, course, nodes, rider, conditions, v0)
    # The 1D on a line that knows its corners ("1dline") slows for them; the plain 1D
    # ignores them (model.md section 6).
    v = speed_guess(course, nodes, rider, conditions, v0, corners=model.name != "1d")
    x = np.zeros((model.nx, len(nodes)))
    x[model.index("v")] = v
    x[model.index("w_n")] = rider.critical_power_w / rider.max_power_w
    x[model.index("e_n")] = 1.0 - 0.95 * (nodes - nodes[0]) / max(nodes[-1] - nodes[0], 1.0)
    return x, np.zeros((model.nu, len(nodes) - 1))


def _pacing_w(flat_w: float, grade: np.ndarray, rider: Rider, conditions: Conditions
              ) -> np.ndarray:
    """Crank power per node of a pacing at `flat_w` on the flat, with the same marginal
    time per joule everywhere in steady state: the speed where
    `v (m g (c_rr cos b + sin b) + 3 k_v v^2)` equals its flat value (`steady_speed_mps`
    with a 3x drag area solves that cubic), so more power on climbs, less on descents.
    (Constant power everywhere instead: bologna 429 iterations against 195.)"""
    k_v = drag_factor_kgpm(rider, conditions)
    eta, mg = rider.drivetrain_efficiency, rider.mass_kg * GRAVITY_MPS2
    v_flat = steady_speed_mps(flat_w, rider, conditions, 0.0)
    marginal = v_flat * (mg * rider.crr + 3 * k_v * v_flat ** 2)
    triple = replace(rider, drag_area_m2=3 * rider.drag_area_m2)
    out = np.empty(len(grade))
    cache: dict[float, float] = {}
    for i, g in enumerate(np.round(grade, 4)):
        if g not in cache:
            v = steady_speed_mps(marginal / eta, triple, conditions, float(g))
            b = math.atan(g)
            cache[g] = min(rider.max_power_w, max(
                0.0, v * resistance_n(v, math.sin(b), math.cos(b), rider, k_v) / eta))
        out[i] = cache[g]
    return out


def _arc_ride(nodes: np.ndarray, rider: Rider, conditions: Conditions, v0: float,
              power_w: np.ndarray, kappa_path: np.ndarray, beta_path: np.ndarray,
              stretch: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quasi-steady ride at crank power `power_w` (per node) on a line of curvature
    `kappa_path`, slope `beta_path` and length `stretch` per metre of centre line (per
    node): speed, W_n, E_n at the nodes.

    Forward: pedal at `power_w`, gated by the steady lean (C15) and by what the lateral
    force leaves of the grip (C16), capped by `_ARC_GRIP` of the lateral limit in corners.
    Backward: brake into what follows at `_ARC_BRAKE` of the grip the lateral force leaves.
    W_n is what each interval's speed change takes (E3 inverted), E_n the Skiba balance
    (E9) of that power.
    """
    m, g, eta = rider.mass_kg, GRAVITY_MPS2, rider.drivetrain_efficiency
    k_v = drag_factor_kgpm(rider, conditions)
    lat = lateral_limit_mps2(rider, conditions)
    grip_x = conditions.mu_x * g
    lean = _PEDAL_LEAN_SHARE * rider.pedal_lean_max_rad
    kappa = np.abs(kappa_path) + 1e-9
    sin_b, cos_b = np.sin(beta_path), np.cos(beta_path)
    v_top = np.sqrt(_ARC_GRIP * lat / kappa)
    ds = np.diff(nodes) * 0.5 * (stretch[1:] + stretch[:-1])
    v = np.empty(len(nodes))
    v[0] = v0
    for i in range(len(ds)):  # forward: pedal where lean and grip allow it
        steps = max(1, math.ceil(ds[i] / _ARC_STEP_M))
        h, vi = ds[i] / steps, v[i]
        for _ in range(steps):
            ay = vi * vi * kappa[i]
            gate = max(0.0, 1.0 - (math.atan(ay / g) / lean) ** 2)
            left = math.sqrt(max(0.0, 1.0 - (ay / lat) ** 2))
            force = min(eta * power_w[i] * gate / vi, grip_x * m * left)
            # In v^2 (exact at constant force): v dv/ds = a blows up in v where slow.
            v2 = vi * vi + 2 * h * (force - resistance_n(vi, sin_b[i], cos_b[i], rider, k_v)) / m
            vi = math.sqrt(max(v2, V_MIN_MPS ** 2))
        v[i + 1] = min(vi, v_top[i + 1])
    for i in range(len(ds) - 1, 0, -1):  # backward: brake into what follows
        vn = v[i + 1]
        left = math.sqrt(max(0.0, 1.0 - (vn * vn * kappa[i + 1] / lat) ** 2))
        decel = (_ARC_BRAKE * grip_x * left
                 + resistance_n(vn, sin_b[i], cos_b[i], rider, k_v) / m)
        v[i] = min(v[i], math.sqrt(max(vn * vn + 2 * decel * ds[i], V_MIN_MPS ** 2)))
    vm = 0.5 * (v[1:] + v[:-1])
    force = (m * (v[1:] ** 2 - v[:-1] ** 2) / (2 * ds)
             + resistance_n(vm, sin_b[:-1], cos_b[:-1], rider, k_v))
    w = np.where(force > 0, force * vm / (eta * rider.max_power_w), force / (grip_x * m))
    w = np.clip(np.append(w, w[-1]), -1.0, 1.0)
    w[0] = rider.critical_power_w / rider.max_power_w  # the start's (course_nlp)
    e = np.empty(len(nodes))
    e[0] = 1.0
    p_plus = rider.max_power_w * np.maximum(w, 0.0)
    for i in range(len(ds)):  # E9 (Skiba)
        rate = float(e_n_rate(e[i], p_plus[i], rider.critical_power_w, rider.w_prime_j))
        e[i + 1] = min(1.0, e[i] + rate * ds[i] / vm[i])
    return v, w, e


def _line(course: Course, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The least-curvature line within the road less `_LINE_MARGIN_M`, starting on the
    centre line: its offset n, heading alpha and curvature at the nodes.

    Minimises the integral of (kappa + n'')^2 (the line's curvature, linearised in n),
    a convex QP with bounds, by OSQP (CasADi's `conic`; 0.01-0.7 s CPU on the study's
    meshes of 600-10,000 nodes; `lsq_linear` took minutes on bologna's 5,000). Why not a
    primal-dual active-set method (the earlier one, as `course.racing_line` uses for the
    shortest line): its Hessian here (fourth differences) is not an M-matrix, and the
    active sets cycled: 6 of the 9 study courses stopped at its 30-step cap with lines
    up to 5.6 m off the optimum (rovereto-like; bologna 4.6 m, loop-4k-2laps 4.3 m).
    Outside-inside-outside through corners, as the optimum rides them; the curvature of
    the line (exact, from n and alpha: E1, E8) is what the guess's speed, lean and
    steering follow.
    """
    kappa = course.at("kappa_per_m", nodes)
    size = len(nodes)
    h = np.diff(nodes)
    hl, hr = h[:-1], h[1:]
    rows = np.arange(size - 2)
    weight = np.sqrt(0.5 * (hl + hr))  # the integral over each node's share of s
    left, right = 2 / (hl * (hl + hr)) * weight, 2 / (hr * (hl + hr)) * weight
    second = sp.csr_matrix((np.concatenate([left, -(left + right), right]),
                            (np.tile(rows, 3), np.concatenate([rows, rows + 1, rows + 2]))),
                           shape=(size - 2, size))
    hess = (second.T @ second).tocsc()
    hess = hess + sp.identity(size, format="csc") * (_LINE_REG * hess.diagonal().mean())
    grad0 = second.T @ (kappa[1:-1] * weight)
    lo = -(course.at("width_right_m", nodes) - _LINE_MARGIN_M)
    hi = course.at("width_left_m", nodes) - _LINE_MARGIN_M
    lo[0] = hi[0] = 0.0
    h_dm = ca.DM(ca.Sparsity(size, size, hess.indptr.tolist(), hess.indices.tolist()),
                 hess.data.tolist())
    qp = ca.conic("line", "osqp", {"h": h_dm.sparsity(), "a": ca.Sparsity(0, size)},
                  _LINE_QP_OPTIONS)
    sol = qp(h=h_dm, g=grad0, lbx=lo, ubx=hi)
    if not qp.stats()["success"]:  # the guess goes on with OSQP's last iterate
        log.warning("3D guess: the least-curvature line's QP stopped unsolved (%s) on %d "
                    "nodes; its last iterate is used, clipped into the road",
                    qp.stats()["return_status"], size)
    n = np.clip(np.asarray(sol["x"]).ravel(), lo, hi)
    alpha = offset_heading_rad(n, nodes, kappa)
    curvature = (kappa + np.gradient(alpha, nodes)) * np.cos(alpha) / (1 - n * kappa)
    return n, alpha, curvature


def arc_guess(model: SpatialModel, course: Course, nodes: np.ndarray, rider: Rider,
              conditions: Conditions, v0: float) -> tuple[np.ndarray, np.ndarray]:
    """The 3D guess: a quasi-steady ride (`_arc_ride`) paced so that W' is spent by
    the finish, on the least-curvature line (`_line`), with the steady lean and
    steering of that line and the rates that join the nodes.

    The cold guess of earlier (speed at CP capped at 0.7 of the lateral limit, W_n at CP
    everywhere, E_n falling linearly) broke C15 at every corner and the continuity of
    speed and W' everywhere; IPOPT then formed the active arcs of C15, C16 and W' >= 0 a
    node or two per iteration (bench/RESULTS.md, H5). From this guess (issue-18 rider,
    default mesh): bologna 199 iterations instead of 470, verona-like 185 / 268,
    tokyo2020 250 / capped at 460, the 2-lap loop 134 / 280, the hairpin course (paper
    rider) 245 / 369; the finish within 0.05 % except where it found a faster optimum
    (verona-like -0.12 %, descent-hairpins -0.23 %, which took 86 iterations / 40).

    Why the line: on the centre line the guess led the short hairpin test courses
    (tests/support/courses.hairpin) into slower local optima than the cold guess
    (25.60 s against 25.09 s at 120 m straights, 45.21 against 44.48 at 300 m), and a
    re-solve of the rest of the 300 m course from that plan failed (311 iterations
    capped, then Restoration_Failed). On the line: 25.47 and 44.20 s, the re-solve
    converges; verona-like 179 iterations (268 cold, 185 on the centre line),
    1633.20 s; the hairpin course with the paper rider 232 (369). The finish of these
    short hairpin courses still depends on the guess (24.9-25.6 s over the variants
    tried: local optima of the line through one hairpin), bench/RESULTS.md 2026-12-02."""
    cp = rider.critical_power_w
    lo, hi = 0.5 * cp, min(rider.max_power_w, cp * 2.0)
    n, alpha, kp = _line(course, nodes)
    kappa = course.at("kappa_per_m", nodes)
    # ds along the line per ds along the centre line, and the line's own slope (E3
    # [fix]): the model rides both.
    stretch = offset_stretch(n, alpha, kappa)
    beta = path_slope_rad(course.at("beta_rad", nodes), n, alpha, kappa)
    grade = np.tan(beta)
    ride = _arc_ride(nodes, rider, conditions, v0, _pacing_w(lo, grade, rider, conditions),
                     kp, beta, stretch)
    if np.min(ride[2]) > _ARC_E_MIN:  # bisect on the pacing power: W' spent by the finish
        for _ in range(_ARC_BISECTIONS):
            mid = 0.5 * (lo + hi)
            trial = _arc_ride(nodes, rider, conditions, v0,
                              _pacing_w(mid, grade, rider, conditions), kp, beta, stretch)
            if np.min(trial[2]) >= _ARC_E_MIN:
                lo, ride = mid, trial
            else:
                hi = mid
    v, w, e = ride
    phi = -np.arctan(v ** 2 * kp / GRAVITY_MPS2)  # steady lean (E5)
    # C15 at the nodes (the ride gates the power within its steps, not at the node).
    gate = 1 - (phi / (_PEDAL_LEAN_SHARE * rider.pedal_lean_max_rad)) ** 2
    w = np.minimum(w, np.maximum(gate, 0.0))
    delta_n = np.arctan(rider.wheelbase_m * kp) / rider.steer_max_rad
    dt = np.diff(nodes) * 0.5 * (stretch[1:] + stretch[:-1]) / (0.5 * (v[1:] + v[:-1]))
    t = np.concatenate([[0.0], np.cumsum(dt)])
    x = np.zeros((model.nx, len(nodes)))
    for name, row in (("n", n), ("alpha", alpha), ("v", v), ("w_n", w), ("e_n", e),
                      ("phi", phi), ("delta_n", delta_n), ("phi_dot", np.gradient(phi, t))):
        x[model.index(name)] = row
    u = np.zeros((model.nu, len(nodes) - 1))
    rates = {"u_w": (w, rider.max_power_w / rider.power_rate_max_wps, U_W_MAX),
             "u_delta": (delta_n, rider.steer_max_rad / rider.steer_rate_max_radps,
                         U_DELTA_MAX)}
    for name, (row, scale, bound) in rates.items():  # E6/E7 inverted: the rates between nodes
        u[model.controls.index(name)] = np.clip(np.diff(row) / dt * scale, -bound, bound)
    return x, u


def plan_rows(plan: Plan) -> set[str]:
    """The states and controls a plan has values of (`plan_guess`): a 1D plan has no
    lateral states and no steering."""
    return set(STATES_1D + CONTROLS_1D) if plan.model == "1d" else set(PLAN_ARRAYS)


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
    has = plan_rows(plan)
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
