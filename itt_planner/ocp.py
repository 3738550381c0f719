"""The minimum-time pacing-and-cornering OCP over a whole course (model.md section 5).

`solve_plan(course, rider, conditions, settings, model="3d"|"1d") -> Plan`:

1. mesh: non-uniform nodes (`mesh.build_mesh`: ~1 m in corners, up to `h_max_m` on
   straights) and the road data per interval;
2. transcription: direct multiple shooting with RK4 (`transcription.transcribe`,
   why in its docstring), hard path constraints C11-C16;
3. solve: IPOPT (MUMPS) from a physically sensible initial guess (a speed profile that
   respects the grip limit in corners, steady lean and steering), or from an existing
   `Plan` interpolated onto the new mesh (`guess=`, e.g. a coarse-mesh plan for a mesh
   study: `plan_guess`), with an iteration and CPU-time cap, so bad settings end with a
   solver status instead of a hang.

Boundary conditions (model.md section 5): upright on the centre line, `W_n = W_C/W_max`,
`E_n = 1`, end state free. Launch: the start speed is raised from `start_speed_mps` just
enough that the start power's tyre force uses at most `_LAUNCH_GRIP` of the grip, which
keeps wet-road starts feasible (model.md, launch note).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from itt_planner.conditions import GRAVITY_MPS2, Conditions
from itt_planner.course import Course
from itt_planner.errors import SolveError
from itt_planner.mesh import build_mesh, road_data
from itt_planner.model import (
    CONTROLS_1D,
    CONTROLS_3D,
    STATES_1D,
    STATES_3D,
    ModelParams,
    SpatialModel,
    build_model,
    steady_speed_mps,
)
from itt_planner.plan import Plan
from itt_planner.rider import Rider
from itt_planner.transcription import Transcription, transcribe
from itt_planner.wprime import WPrimeModel

log = logging.getLogger(__name__)

#: Share of the grip the launch may use at the start node (model.md launch note).
_LAUNCH_GRIP = 0.8
#: Share of the lateral grip the initial guess uses in corners.
_GUESS_GRIP = 0.7
#: Bounds on the normalised rates u (model.md C13/C14 note: loose, for robustness).
U_DELTA_MAX = 20.0
U_W_MAX = 50.0
#: Lowest speed the NLP allows (keeps 1/s_dot finite), m/s.
V_MIN_MPS = 0.5
#: Interval length (m) above which the RK4 integrator takes several substeps.
_SUBSTEP_M = 4.0
#: IPOPT's bound_push = bound_frac (how far the initial point is moved inside its
#: bounds): IPOPT's default 1e-2 first. 1e-4 took 116 instead of 75 iterations on
#: verona-like 3D (and ended 0.08 % slower, in another local optimum), and 127 instead of
#: 61 on rovereto-like 1D (34 instead of 43 on verona-like 1D).
_BOUND_PUSH = 1e-2
#: A solve that ends in one of these statuses is restarted once with this push: on
#: short courses (0.6-0.8 km, typical and climber riders) the 3D model ended in
#: Restoration_Failed with the default push and converged in 39-64 iterations with it.
_RETRY_BOUND_PUSH = 1e-4
_RETRY_STATUSES = ("Restoration_Failed", "Error_In_Step_Computation",
                   "Infeasible_Problem_Detected")
#: The `Plan` array of each state and control of the spatial models.
PLAN_ARRAYS = {"n": "n_m", "alpha": "alpha_rad", "phi": "phi_rad", "phi_dot": "phi_dot_radps",
               "v": "v_mps", "w_n": "w_n", "delta_n": "delta_n", "e_n": "e_n",
               "u_delta": "u_delta", "u_w": "u_w"}


@dataclass(frozen=True)
class OcpSettings:
    """Mesh, boundary and solver settings of the full-course OCP.

    Attributes:
        h_min_m, h_max_m: finest and coarsest mesh intervals (3D).
        h_max_1d_m: coarsest mesh interval of the 1D model.
        uniform_m: if set, a uniform mesh of this spacing instead (for mesh studies).
        margin_m: distance kept from each road edge (half the bike width + safety), C11.
        start_speed_mps: speed at the start line (raised for low grip, see module doc).
        e_final_min: lower bound on E_n at the finish (C12).
        w_delta, w_power: objective weights w_1, w_2 (model.md section 5).
        wprime_model: E9 variant.
        max_iter, max_cpu_time_s: hard caps of the solver.
        tol: IPOPT's convergence tolerance.
        jit: compile the stage kernels to C with the machine's compiler (cached).
    """

    h_min_m: float = 1.0
    # Longer intervals make each shooting interval span up to ~1 s of the unstable roll
    # mode at climbing speeds; IPOPT then needed 1e14 regularisation and did not converge.
    h_max_m: float = 4.0
    # The 1D model has no roll mode: coarser intervals are accurate and converge.
    h_max_1d_m: float = 10.0
    uniform_m: float | None = None
    margin_m: float = 0.5
    start_speed_mps: float = 1.0
    e_final_min: float = 0.0
    w_delta: float = 0.01
    w_power: float = 0.01
    wprime_model: WPrimeModel = WPrimeModel.SKIBA
    max_iter: int = 400
    max_cpu_time_s: float = 120.0
    tol: float = 1e-6
    jit: bool = True


@dataclass(frozen=True)
class Start:
    """A solve from mid-course: the rest of the course from `s_m`, from a rider's state.

    Attributes:
        s_m: where the solve starts (the plan's `s_m[0]`; its `t_s` counts from there).
        state: model state name (`STATES_3D`) -> value at `s_m`; a state not given
            keeps its launch value (model.md section 5), a state the model does not
            have is ignored. Values outside the simple bounds (a rider measured off the
            road) are clipped into them.
    """

    s_m: float
    state: Mapping[str, float]


def substeps_for(h_max_m: float) -> int:
    """RK4 substeps so that no substep exceeds `_SUBSTEP_M` (roll time constant ~0.45 s)."""
    return max(1, math.ceil(h_max_m / _SUBSTEP_M - 1e-9))


@lru_cache(maxsize=16)
def _model(kind: str, wprime_model: WPrimeModel) -> SpatialModel:
    return build_model(kind, wprime_model)


@lru_cache(maxsize=8)
def _solver(kind: str, wprime_model: WPrimeModel, n_intervals: int, substeps: int,
            jit: bool, max_iter: int, max_cpu_time_s: float, tol: float, bound_push: float
            ) -> tuple[Transcription, ca.Function]:
    """The NLP and its IPOPT solver for one node count (built once per process)."""
    tr = transcribe(_model(kind, wprime_model), n_intervals, substeps=substeps, compile_c=jit)
    opts = {**tr.derivatives,
        "ipopt.max_iter": max_iter, "ipopt.max_cpu_time": max_cpu_time_s, "ipopt.tol": tol,
        "ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
        # Measured on verona-like: adaptive 75 iterations (3D) / 43 (1D), monotone 239 / >400.
        "ipopt.mu_strategy": "adaptive",
        "ipopt.linear_solver": "mumps",
        "ipopt.bound_push": bound_push, "ipopt.bound_frac": bound_push,
        "error_on_fail": False,
        # Derivatives come from the compiled stage kernels (transcription docstring); the
        # Lagrangian gradient w.r.t. p that nlpsol would build by AD is not needed.
        "no_nlp_grad": True, "calc_lam_p": False,
    }
    return tr, ca.nlpsol(f"ocp_{kind}_{n_intervals}", "ipopt", tr.nlp, opts)


def start_speed(rider: Rider, conditions: Conditions, settings: OcpSettings) -> float:
    """Start speed: at least `start_speed_mps`, and enough for the start power's grip."""
    grip_force = _LAUNCH_GRIP * conditions.mu_x * GRAVITY_MPS2 * rider.mass_kg
    return max(settings.start_speed_mps, rider.critical_power_w / grip_force, V_MIN_MPS)


def check_inputs(course: Course, rider: Rider, settings: OcpSettings) -> None:
    """Reject inputs no solver can use.

    Raises:
        SolveError: status "invalid_input": the road is narrower than the bike anywhere.
    """
    room = course.width_left_m + course.width_right_m - 2 * settings.margin_m
    if np.any(room <= 0):
        i = int(np.argmin(room))
        msg = (f"course {course.name!r}: road at s = {course.s_m[i]:.0f} m is "
               f"{course.width_left_m[i] + course.width_right_m[i]:.2f} m wide, narrower than "
               f"the bike and margins ({2 * settings.margin_m:.2f} m)")
        raise SolveError(msg, status="invalid_input")
    del rider  # validated by Rider itself


def speed_guess(course: Course, nodes: np.ndarray, rider: Rider, conditions: Conditions,
                v0: float, corners: bool) -> np.ndarray:
    """A speed profile to start from: steady speed at CP on the local grade, capped by
    `_GUESS_GRIP` of the lateral grip in corners, with bounded acceleration/deceleration."""
    grade = np.tan(course.at("beta_rad", nodes))
    v = np.array([steady_speed_mps(rider.critical_power_w, rider, conditions, g) for g in grade])
    v = np.maximum(v, 2.0)
    if corners:
        kappa = np.abs(course.at("kappa_per_m", nodes)) + 1e-9
        v = np.minimum(v, np.sqrt(_GUESS_GRIP * conditions.mu_y * GRAVITY_MPS2 / kappa))
    ds = np.diff(nodes)
    v[0] = v0
    for i in range(1, len(v)):  # accelerate at <= 1 m/s^2
        v[i] = min(v[i], math.sqrt(v[i - 1] ** 2 + 2 * 1.0 * ds[i - 1]))
    for i in range(len(v) - 2, 0, -1):  # brake at <= 3 m/s^2
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2 * 3.0 * ds[i]))
    return v


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
    (`to_plan`), so each new interval takes the control of the plan interval that holds
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


def bounds(model: SpatialModel, course: Course, nodes: np.ndarray, rider: Rider,
           settings: OcpSettings, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Simple bounds on the states and controls per node (C11-C14, v >= v_min)."""
    n = len(nodes)
    lbx = np.full((model.nx, n), -np.inf)
    ubx = np.full((model.nx, n), np.inf)
    lbx[model.index("v")] = V_MIN_MPS
    lbx[model.index("w_n")], ubx[model.index("w_n")] = -1.0, 1.0  # C13
    lbx[model.index("e_n")], ubx[model.index("e_n")] = 0.0, 1.0  # C12
    lbx[model.index("e_n"), -1] = settings.e_final_min
    if model.name == "3d":
        lbx[model.index("n")] = -(course.at("width_right_m", nodes) - settings.margin_m)  # C11
        ubx[model.index("n")] = course.at("width_left_m", nodes) - settings.margin_m
        lbx[model.index("delta_n")], ubx[model.index("delta_n")] = -1.0, 1.0  # C14
        lbx[model.index("alpha")], ubx[model.index("alpha")] = -1.0, 1.0
        lbx[model.index("phi")], ubx[model.index("phi")] = -1.2, 1.2
    lbx[:, 0] = ubx[:, 0] = np.clip(x0, lbx[:, 0], ubx[:, 0])
    u_max = np.array([U_DELTA_MAX, U_W_MAX])[-model.nu:, None]
    lbu = np.repeat(-u_max, n - 1, axis=1)
    return (lbx, ubx), (lbu, -lbu)


def solve_plan(course: Course, rider: Rider, conditions: Conditions = Conditions(),
               settings: OcpSettings = OcpSettings(), *, model: str = "3d",
               guess: Plan | None = None, start: Start | None = None) -> Plan:
    """Solve the minimum-time OCP over the whole course and return the `Plan`.

    `start`: solve the rest of the course from a rider's state instead (the pacing
    engine's re-plan after the rider left the plan); the end conditions stay.

    `guess`: start IPOPT from this plan (any mesh, either model; `plan_guess`) instead
    of the default guess; the boundary conditions stay those of `rider`/`conditions`.
    Only the primal point is warm (a Plan keeps no multipliers), with the same IPOPT
    options as a cold solve (`mu_init` would not matter: the adaptive barrier update
    ignores it; measured identical). Measured on verona-like 3D, uniform 1 m mesh
    (16,800 nodes): cold, not converged in 400 iterations; from the non-uniform plan,
    converged in 687 iterations (642 s CPU).

    A solve that does not converge (iteration/time cap, infeasible) still returns a Plan,
    with `solver_status` saying so. A solve that fails early (`_RETRY_STATUSES`) is
    restarted once from the same guess with a smaller bound push, so the worst case is
    twice the iteration/time cap.

    Raises:
        SolveError: unusable input (status "invalid_input"), e.g. a road narrower than the
            bike, or an unknown model name.
    """
    if model not in ("3d", "1d"):
        raise SolveError(f"unknown model {model!r}: choose '3d' or '1d'", status="invalid_input")
    check_inputs(course, rider, settings)
    t_start = time.perf_counter()
    h_max = settings.h_max_m if model == "3d" else settings.h_max_1d_m
    nodes = build_mesh(course, settings.h_min_m, h_max, settings.uniform_m,
                       start_m=0.0 if start is None else start.s_m)
    n = len(nodes) - 1
    substeps = substeps_for(float(np.max(np.diff(nodes)))) if model == "3d" else 1
    caps = (settings.jit, settings.max_iter, settings.max_cpu_time_s, settings.tol)
    tr, solver = _solver(model, settings.wprime_model, n, substeps, *caps, _BOUND_PUSH)
    spm = tr.model
    par = ModelParams(rider, conditions, settings.w_delta, settings.w_power).vector()
    v0 = start_speed(rider, conditions, settings)
    if start is not None:
        v0 = float(start.state.get("v", v0))
    x_guess, u_guess = initial_guess(spm, course, nodes, rider, conditions, v0)
    x0 = x_guess[:, 0].copy()
    if start is not None:
        for name, value in start.state.items():
            if name in spm.states:
                x0[spm.index(name)] = value
    if guess is not None:
        x_guess, u_guess = plan_guess(spm, guess, nodes, x_guess, u_guess)
    (lbx, ubx), (lbu, ubu) = bounds(spm, course, nodes, rider, settings, x0)
    if start is not None:
        # The guess's W' re-anchored at the start's: a rider off the plan has a deficit
        # (or a surplus) the whole rest of the guess would otherwise ignore.
        ie = spm.index("e_n")
        x_guess[ie] = x_guess[ie] - (x_guess[ie, 0] - lbx[ie, 0])
    x_guess[:, 0] = lbx[:, 0]
    lay = tr.layout
    p = tr.params(road_data(course, nodes), par)
    t_build = time.perf_counter() - t_start
    args = {"x0": lay.join(np.clip(x_guess, lbx, ubx), u_guess), "p": p,
            "lbx": lay.join(lbx, lbu), "ubx": lay.join(ubx, ubu), "lbg": tr.lbg, "ubg": tr.ubg}
    sol = solver(**args)
    stats = solver.stats()
    status = str(stats.get("return_status", "unknown"))
    iterations = int(stats.get("iter_count", 0))
    if status in _RETRY_STATUSES:
        log.info("full-course %s OCP on %s: %s, restarting with a smaller bound push",
                 model, course.name, status)
        _, solver = _solver(model, settings.wprime_model, n, substeps, *caps, _RETRY_BOUND_PUSH)
        sol = solver(**args)
        stats = solver.stats()
        status = str(stats.get("return_status", "unknown"))
        iterations += int(stats.get("iter_count", 0))
    elapsed = time.perf_counter() - t_start
    if not stats.get("success", False):
        log.warning("full-course %s OCP on %s: %s after %s iterations", model, course.name,
                    status, stats.get("iter_count"))
    w = np.asarray(sol["x"]).ravel()
    meta = {"course": course.name, "course_sha256": course.source_sha256,
            "rider": asdict(rider), "conditions": asdict(conditions),
            "settings": {k: (v.value if isinstance(v, WPrimeModel) else v)
                         for k, v in asdict(settings).items()},
            "build_time_s": t_build, "objective": float(sol["f"]),
            "success": bool(stats.get("success", False))}
    if start is not None:
        meta["start"] = {"s_m": start.s_m, "state": dict(start.state)}
    if guess is not None:
        meta["guess"] = {"model": guess.model, "n_nodes": guess.n_nodes,
                         "finish_time_s": guess.finish_time_s}
    return to_plan(tr, w, p, np.asarray(sol["lam_g"]).ravel(), nodes, rider, status=status,
                   iterations=iterations, solve_time_s=elapsed, meta=meta)


def to_plan(tr: Transcription, w: np.ndarray, p: np.ndarray, lam_g: np.ndarray,
            nodes: np.ndarray, rider: Rider, *, status: str, iterations: int,
            solve_time_s: float, meta: dict) -> Plan:
    """Turn a numeric NLP solution (primal `w`, constraint multipliers `lam_g`) into a
    `Plan` (SI units, lateral arrays 0 for 1D)."""
    spm, lay = tr.model, tr.layout
    x, u, _ = lay.split(w)
    # The multiplier of the continuity gap `F(x_k) - x_{k+1}` is d(objective)/d(x_{k+1}):
    # the adjoint. Node 0 is fixed by its bounds; it takes node 1's value.
    lam_v = lam_g[: lay.nx * lay.n_intervals].reshape(lay.n_intervals, lay.nx)[:, spm.index("v")]
    dt, y = (np.asarray(a) for a in tr.evaluate(w, p))
    t = np.concatenate([[0.0], np.cumsum(dt.ravel())])
    zeros = np.zeros(len(nodes))

    def state(name: str) -> np.ndarray:
        return x[spm.index(name)] if name in spm.states else zeros

    def control(name: str) -> np.ndarray:
        row = u[spm.controls.index(name)] if name in spm.controls else zeros[:-1]
        return np.append(row, row[-1])  # controls hold over intervals; repeat the last

    arrays = ({PLAN_ARRAYS[name]: state(name) for name in STATES_3D}
              | {PLAN_ARRAYS[name]: control(name) for name in CONTROLS_3D})
    return Plan(
        model=spm.name, s_m=np.asarray(nodes, float), t_s=t, **arrays, power_w=y[0],
        w_prime_j=state("e_n") * rider.w_prime_j, ax_mps2=y[1], ay_mps2=y[2],
        friction_use=y[3], costate_v_s_per_mps=np.concatenate([lam_v[:1], lam_v]),
        solver_status=status, iterations=iterations,
        solve_time_s=solve_time_s, meta=meta,
    )



def longest_stretch(course: Course, climbing: bool, grade_min: float = 0.01
                    ) -> tuple[float, float]:
    """(start, end) in m of the longest stretch steeper than `grade_min` up (`climbing`)
    or down; (0, 0) if there is none."""
    grade = np.tan(course.beta_rad)
    steep = grade > grade_min if climbing else grade < -grade_min
    best, start = (0.0, 0.0), None
    for i, d in enumerate(np.append(steep, False)):
        if d and start is None:
            start = i
        elif not d and start is not None:
            if course.s_m[i - 1] - course.s_m[start] > best[1] - best[0]:
                best = (float(course.s_m[start]), float(course.s_m[i - 1]))
            start = None
    return best


def longest_descent(course: Course) -> tuple[float, float]:
    """(start, end) in m of the longest stretch that loses height (grade < -1 %)."""
    return longest_stretch(course, climbing=False)


def compare_riders(course: Course, conditions: Conditions = Conditions(),
                   settings: OcpSettings = OcpSettings()) -> list[dict]:
    """The three virtual riders (model.md section 7) x both models on one course.

    Per row: finish time, time on the longest descent and on the longest climb, time
    through the sharpest corner.
    """
    from itt_planner.rider import PRESETS  # noqa: PLC0415

    d0, d1 = longest_descent(course)
    c0, c1 = longest_stretch(course, climbing=True)
    sharpest = min(course.corners, key=lambda c: c.min_radius_m, default=None)
    rows = []
    for name in ("typical", "specialist", "climber"):
        for kind in ("3d", "1d"):
            plan = solve_plan(course, PRESETS[name], conditions, settings, model=kind)
            corner_t = (float(plan.at("t_s", sharpest.exit_s_m) - plan.at("t_s", sharpest.entry_s_m))
                        if sharpest else 0.0)
            rows.append({"rider": name, "model": kind, "finish_time_s": round(plan.finish_time_s, 2),
                         "descent_time_s": round(float(plan.at("t_s", d1) - plan.at("t_s", d0)), 2),
                         "climb_time_s": round(float(plan.at("t_s", c1) - plan.at("t_s", c0)), 2),
                         "corner_time_s": round(corner_t, 2), "solver_status": plan.solver_status,
                         "solve_time_s": round(plan.solve_time_s, 2)})
    return rows
