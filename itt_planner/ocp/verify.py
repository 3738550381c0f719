"""Independent check of a solved plan: replay its controls and compare (issue 18).

The OCP integrates the dynamics with one RK4 step (or a few) per mesh interval, in the
spatial domain, where `dv/ds = a / v` is stiff at low speed: a coarse step there can
create speed out of nothing, and IPOPT will happily ride on such an artefact (a plan that
braked to 0.5 m/s and then "accelerated" to 258 m/s within 10 m came out as
`Solve_Succeeded`). So every full-course plan is replayed here:

- Longitudinal replay (both models): the plan's power/braking command `W_n(s)` and, for
  3D, its line (`n(s)`, `alpha(s)`) are the inputs of a forward simulation of E3 (speed),
  E9 (W') and time, with an adaptive integrator (SUNDIALS CVODES, rtol 1e-6) - not the
  transcription's RK4 - on the course's own road data (slope, curvature and heading of
  the course grid, not the mesh's interval means; the slope that of the plan's line,
  `model.dynamics.path_slope_rad`) and with the exact, unsmoothed E3
  (`max(W_n, 0)`, `|v - V_w|`). E9 keeps the model's softplus switch at CP
  (`model.dynamics.E9_SHARPNESS_W`): it is part of the model, not of the transcription, and
  with the exact kink a plan that rides at CP for half an hour differs by kJ (the
  softplus depletes ~3.5 W at exactly CP). The step is adaptive with a cap
  (`_MAX_STEP_M`) so that no mesh interval's power can be stepped over. Speed starts
  from the plan's start speed and is free after that, so an integration artefact shows
  as a speed, time or W' mismatch.
- Path constraints (every model given): C16 and C15 (`model.path`) at the plan's
  nodes, with the course's curvature on the nodes' scale (`node_curvature`, as the
  OCP has it): the 1D model on a line (`build_1d_line`) reads its corners from it, so
  a plan of another model, or one that left its constraints, cannot pass as one.
- Lateral check (3D): the roll mode is an unstable pendulum (~0.45 s), so an open-loop
  replay of the steering over a whole course diverges whatever the plan; instead every
  interval is re-integrated from the plan's node with a 16x finer RK4 step (one
  vectorised CasADi call) and the end state compared with the plan's next node.

Tolerances (`VerifyTolerance`, documented there) are loose enough for the difference
between the transcription's smoothing and the exact physics, tight enough that a
transcription artefact cannot pass. A plan outside them is `invalid` (`solver.PlanStatus`).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass
from typing import Any

import casadi as ca
import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.dynamics import E9_SHARPNESS_W, SpatialModel, path_slope_rad, rk4_step
from itt_planner.model.params import ModelParams
from itt_planner.model.rider import Rider
from itt_planner.model.steady import drag_factor_kgpm
from itt_planner.model.wprime import WPrimeModel, e_n_rate
from itt_planner.ocp.guess import PLAN_ARRAYS
from itt_planner.ocp.mesh import road_data
from itt_planner.ocp.plan import Plan

#: Substeps of the fine RK4 of the lateral check, per transcription substep.
_FINE_FACTOR = 16
#: Largest step of the adaptive replay (m): below the coarsest mesh interval.
_MAX_STEP_M = 5.0
#: The replay's integrator (`_replay`): relative tolerance 1e-6, absolute 1e-7 on speed
#: (m/s), W' (of W'_0) and time (s); no step longer than `_MAX_STEP_M`.
_CVODES_OPTIONS: dict[str, Any] = {
    "reltol": 1e-6, "abstol": 1e-7, "max_step_size": _MAX_STEP_M, "max_num_steps": 100_000,
    "linear_multistep_method": "adams", "nonlinear_solver_iteration": "functional",
    "disable_internal_warnings": True}


@dataclass(frozen=True)
class VerifyTolerance:
    """What the replay may differ from the plan by (SI units).

    Attributes:
        speed_abs_mps, speed_rel: the speed mismatch allowed at any node:
            `speed_abs_mps + speed_rel * v_plan`. The smoothed E3 of the OCP (max(W_n, 0)
            within ~1 W, |v - V_w| within 0.1 m/s) and the power held linear in `s`
            between nodes (the plan holds its rate in time) account for a few 0.01 m/s;
            the artefact of issue 18 was 250 m/s.
        time_rel, time_abs_s: mismatch of the elapsed time at any node:
            `time_abs_s + time_rel * t_plan`.
        w_prime_j, w_prime_rel: mismatch of W' at any node:
            `w_prime_j + w_prime_rel * W'_0` (the E9 switch is smoothed over ~5 W in the OCP).
        lateral_m, heading_rad, roll_rad: 3D only, largest per-interval defect of the
            lateral offset, relative heading and lean against the fine re-integration.
        path: largest value of a path constraint `g <= 0` at a node (C16's friction use
            squared minus 1: 0.04 is a friction use of 1.02, `line_plan.line_corners`'s
            slack; C15's W_n over its gate). A converged plan has them <= IPOPT's
            tolerance; the plain 1D through a 15 m bend has 3 (tests/ocp/test_line_model.py).
    """

    speed_abs_mps: float = 0.3
    speed_rel: float = 0.02
    time_rel: float = 0.003
    time_abs_s: float = 0.5
    w_prime_j: float = 300.0
    w_prime_rel: float = 0.03
    lateral_m: float = 0.05
    heading_rad: float = 0.01
    roll_rad: float = 0.02
    path: float = 0.04


@dataclass(frozen=True)
class Verification:
    """The result of `verify_plan` (SI units). `worst` names the largest mismatch
    relative to its tolerance and `worst_s_m` where it is."""

    verified: bool
    max_speed_error_mps: float
    max_speed_error_s_m: float
    finish_time_error_s: float
    max_time_error_s: float
    max_w_prime_error_j: float
    max_w_prime_error_s_m: float
    max_lateral_defect_m: float
    max_heading_defect_rad: float
    max_roll_defect_rad: float
    max_path_violation: float
    worst: str
    worst_s_m: float
    worst_ratio: float
    replay_finish_s: float
    check_time_s: float
    #: 3D: where the intervals start whose lateral, heading or roll defect exceeds its
    #: tolerance: the transcription's step does not resolve the dynamics there (the
    #: restarts split them: `course_refine.refine`).
    unresolved_s_m: tuple[float, ...] = ()

    def as_dict(self) -> dict[str, float | bool | str | int]:
        """JSON-ready figures (rounded; the unresolved intervals counted)."""
        out: dict[str, float | bool | str | int] = {
            k: (round(v, 4) if isinstance(v, float) else v)
            for k, v in asdict(self).items() if k != "unresolved_s_m"}
        out["unresolved_intervals"] = len(self.unresolved_s_m)
        return out


def verify_plan(plan: Plan, course: Course, rider: Rider, conditions: Conditions = Conditions(),
                *, model: SpatialModel | None = None, substeps: int = 1,
                wprime_model: WPrimeModel = WPrimeModel.SKIBA,
                tolerance: VerifyTolerance = VerifyTolerance()) -> Verification:
    """Replay `plan`'s controls (module docstring) and compare with the plan.

    `model` enables the path check (`model.path`) and, 3D, the lateral check with the
    transcription's `substeps`.
    A replay that cannot be integrated (non-finite plan, a speed that collapses to 0)
    is a failed verification, never an exception.
    """
    t0 = time.perf_counter()
    v_sim, t_sim, w_sim = _replay(plan, course, rider, conditions, wprime_model)
    finite = bool(np.all(np.isfinite(v_sim)) and np.all(np.isfinite(t_sim)))
    if not finite:
        v_sim = np.nan_to_num(v_sim, nan=0.0)
        t_sim = np.nan_to_num(t_sim, nan=np.inf)
        w_sim = np.nan_to_num(w_sim, nan=0.0)
    tol = tolerance
    dv = np.abs(v_sim - plan.v_mps)
    dt = np.abs(t_sim - plan.t_s)
    dw = np.abs(w_sim - plan.w_prime_j)
    ratios = {
        "speed": dv / (tol.speed_abs_mps + tol.speed_rel * plan.v_mps),
        "time": dt / (tol.time_abs_s + tol.time_rel * plan.t_s),
        "w_prime": dw / (tol.w_prime_j + tol.w_prime_rel * rider.w_prime_j),
    }
    lateral = {"lateral": 0.0, "heading": 0.0, "roll": 0.0, "path": 0.0}
    unresolved = np.zeros(plan.n_nodes - 1, bool)
    if model is not None:
        over = np.max(np.maximum(_path_values(plan, course, rider, conditions, model), 0.0),
                      axis=0)
        lateral["path"] = float(np.max(over))
        ratios["path"] = over / tol.path
    if model is not None and model.name == "3d":
        defects = _interval_defects(plan, course, rider, conditions, model, substeps)
        for key, name, scale in (("lateral", "n", tol.lateral_m),
                                 ("heading", "alpha", tol.heading_rad),
                                 ("roll", "phi", tol.roll_rad)):
            d = np.abs(defects[model.index(name)])
            lateral[key] = float(np.max(d)) if d.size else 0.0
            ratios[key] = np.concatenate([[0.0], d / scale])
            unresolved |= d > scale
    worst, worst_i, worst_ratio = "none", 0, 0.0
    for name, r in ratios.items():
        i = int(np.argmax(r))
        if r[i] > worst_ratio:
            worst, worst_i, worst_ratio = name, i, float(r[i])
    iv, iw = int(np.argmax(dv)), int(np.argmax(dw))
    return Verification(
        verified=finite and worst_ratio <= 1.0,
        max_speed_error_mps=float(dv[iv]), max_speed_error_s_m=float(plan.s_m[iv]),
        finish_time_error_s=float(t_sim[-1] - plan.t_s[-1]), max_time_error_s=float(np.max(dt)),
        max_w_prime_error_j=float(dw[iw]), max_w_prime_error_s_m=float(plan.s_m[iw]),
        max_lateral_defect_m=lateral["lateral"], max_heading_defect_rad=lateral["heading"],
        max_roll_defect_rad=lateral["roll"], max_path_violation=lateral["path"],
        worst=worst if finite else "non-finite replay",
        worst_s_m=float(plan.s_m[worst_i]), worst_ratio=worst_ratio if finite else math.inf,
        replay_finish_s=float(t_sim[-1]), check_time_s=time.perf_counter() - t0,
        unresolved_s_m=tuple(map(float, plan.s_m[:-1][unresolved])))


def _replay(plan: Plan, course: Course, rider: Rider, conditions: Conditions,
            wprime_model: WPrimeModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Speed, elapsed time and W' (J) of the forward simulation at the plan's nodes.

    The plan's command and line are linear in `s` between its nodes, the course's
    curvature and heading linear on its grid, its slope constant over each grid cell
    (the altitude's own finite difference): looked up by CasADi's linear interpolants.
    Why SUNDIALS CVODES (Adams, functional iteration) and not SciPy's RK45 with a
    Python right-hand side: a quarter of the cost though it takes about twice the steps
    (48,349 against 22,996 on Ardennes: the slope's jump at every grid cell sets the
    step, and no Python runs per step), 0.24 s against 1.02 s on the Zwift
    Bologna 3D plan (4,253 nodes), 0.9 s against 3.6 s on Ardennes (14,695), a fifth of
    every re-solve of the rest of the course; and closer to the exact solution at the
    same tolerance (finish within 0.013 s of a 1e-10 run, RK45 0.051 s; bench/RESULTS.md,
    2026-12-03, fourth session).
    """
    y0 = [float(plan.v_mps[0]), float(plan.e_n[0]), 0.0]
    # CasADi's fmax/fmin map NaN to the other argument: a NaN command would replay as 0 W.
    if not all(np.all(np.isfinite(a)) for a in (plan.w_n, plan.n_m, plan.alpha_rad, y0)):
        nan = np.full(plan.n_nodes, np.nan)
        return nan, nan, nan
    s, y = ca.MX.sym("s"), ca.MX.sym("y", 3)
    nodes = plan.s_m
    along = ca.interpolant("plan_inputs", "linear", [nodes],
                           np.vstack([plan.w_n, plan.n_m, plan.alpha_rad]).ravel(order="F"))
    w_n, n, alpha = ca.vertsplit(along(s))
    ds_c, grid = course.ds_m, course.s_m
    road = ca.interpolant("road", "linear", [grid],
                          np.vstack([course.kappa_per_m, course.theta_rad]).ravel(order="F"))
    kappa, theta = ca.vertsplit(road(s))
    cell_slope = ca.interpolant("cell_slope", "linear", [grid[:-1]],
                                np.arctan(np.diff(course.z_m) / ds_c))
    cell = ca.fmin(ca.fmax(ca.floor(s / ds_c), 0), len(grid) - 2)
    # E3 on the slope of the plan's own line (`path_slope_rad`), as the models ride.
    beta = path_slope_rad(cell_slope(cell * ds_c), n, alpha, kappa)
    g, m = GRAVITY_MPS2, rider.mass_kg
    k_v = drag_factor_kgpm(rider, conditions)
    wind_e, wind_n = conditions.wind_enu_mps()
    v = ca.fmax(y[0], 0.05)
    psi = theta + alpha
    s_dot = v * ca.cos(alpha) / (1.0 - n * kappa)
    p_plus = rider.max_power_w * ca.fmax(w_n, 0.0)
    p_brake = conditions.mu_x * g * m * v * ca.fmin(w_n, 0.0)
    v_air = v - (wind_e * ca.cos(psi) + wind_n * ca.sin(psi))
    accel = ((rider.drivetrain_efficiency * p_plus + p_brake) / (m * v)
             - g * (rider.crr * ca.cos(beta) + ca.sin(beta)) - k_v * v_air * ca.fabs(v_air) / m)
    e_dot = e_n_rate(y[1], p_plus, rider.critical_power_w, rider.w_prime_j, wprime_model,
                     sharpness_w=E9_SHARPNESS_W)
    dae: dict[str, Any] = {"t": s, "x": y, "ode": ca.vertcat(accel, e_dot, 1.0) / s_dot}
    try:
        replay = ca.integrator("replay", "cvodes", dae,
                               float(nodes[0]), nodes[1:].tolist(), _CVODES_OPTIONS)
        ends = np.asarray(replay(x0=y0)["xf"])
    except RuntimeError:  # the integrator gave up (a speed that collapses to 0)
        ends = np.full((3, plan.n_nodes - 1), np.nan)
    out = np.hstack([np.array(y0)[:, None], ends])
    return out[0], out[2], out[1] * rider.w_prime_j


def _path_values(plan: Plan, course: Course, rider: Rider, conditions: Conditions,
                 model: SpatialModel) -> np.ndarray:
    """`model.path` at every node of `plan` (rows: constraints, columns: nodes), with the
    road data of the OCP except the curvature: the course's own at the node."""
    x = np.vstack([getattr(plan, PLAN_ARRAYS[name]) for name in model.states])
    road = road_data(course, plan.s_m)
    road = np.hstack([road, road[:, -1:]])
    road[0] = node_curvature(course, plan.s_m)
    par = ModelParams(rider, conditions).vector()
    values: np.ndarray = np.asarray(model.path.map(plan.n_nodes)(x, road, par))
    return values


def node_curvature(course: Course, s_m: np.ndarray) -> np.ndarray:
    """The course's curvature at the nodes `s_m` on their own scale, as the OCP's path
    constraints have it (`transcription`): the heading change over each node's two
    intervals by their length (the first and last node: their one interval's). Why not
    `kappa_per_m` at the node: on a line course (`racing_line.offset_course`) that is
    the derivative of a resampled polyline, noise at the grid's scale: on the Zwift
    Bologna 3D plan's line it asked up to 13.8 m/s^2 at the plan's speeds where the
    plan's own path (tan(delta)/L) had 9.8; on the nodes' scale 11.1 (helper H2)."""
    turn = np.diff(course.at("theta_rad", s_m))
    h = np.diff(s_m)
    kappa: np.ndarray = ((np.append(0.0, turn) + np.append(turn, 0.0))
                         / (np.append(0.0, h) + np.append(h, 0.0)))
    return kappa


def _interval_defects(plan: Plan, course: Course, rider: Rider, conditions: Conditions,
                      model: SpatialModel, substeps: int) -> np.ndarray:
    """Fine-RK4 end state of every interval from the plan's node minus the plan's next node.

    The road data per interval are those of the OCP (`mesh.road_data`): this check is
    about the integration of each interval, the longitudinal replay about the road.
    """
    x = np.vstack([getattr(plan, PLAN_ARRAYS[name]) for name in model.states])
    u = np.vstack([getattr(plan, PLAN_ARRAYS[name])[:-1] for name in model.controls])
    road = road_data(course, plan.s_m)
    par = ModelParams(rider, conditions).vector()
    n = plan.n_nodes - 1
    fine = rk4_step(model, substeps * _FINE_FACTOR).map(n)
    x_end = np.asarray(fine(x[:, :-1], u, road, ca.repmat(par, 1, n))[0])
    defect: np.ndarray = x_end - x[:, 1:]
    return defect
