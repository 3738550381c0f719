"""The minimum-time pacing-and-cornering OCP over a whole course (model.md section 5).

`solve_plan(course, rider, conditions, settings, model="3d"|"1d") -> Plan`:

1. mesh: non-uniform nodes (`mesh.build_mesh`: ~1 m in corners, up to `h_max_m` on
   straights) and the road data per interval;
2. transcription: direct multiple shooting with RK4 (`transcription.transcribe`,
   why in its docstring), hard path constraints C11-C16;
3. solve: IPOPT (MUMPS) from a physically sensible initial guess (a speed profile that
   respects the grip limit in corners, steady lean and steering), or from an existing
   `Plan` interpolated onto the new mesh (`guess=`, e.g. a coarse-mesh plan for a mesh
   study: `plan_guess`), with an iteration and time budget scaled to the course
   length (`OcpSettings.budget`), so bad settings end with a solver status instead of a
   hang;
4. verify: every plan is replayed by an independent simulation (`verify.verify_plan`);
   a converged plan that fails it is `invalid` (`solver.PlanStatus`), never a success.

Restart strategies (issue 14 item 2, issue 18 item 3), in this order, each only when the
previous attempt did not end converged and verified, all within the budget (the first
start may use `_FIRST_SHARE` of it):

- early failure (`_RETRY_STATUSES`): the same start with a smaller bound push (on short
  courses the 3D model ended in Restoration_Failed with IPOPT's default push and
  converged in 39-64 iterations with 1e-4);
- 1D: a cold start on a mesh of half the spacing (the 1D model on the 9 km hilly route
  of bench_convergence with 20 m intervals stopped at 569 iterations; restarted on
  10 m it converged in 65);
- 3D without a given guess: warm start from the 1D plan of the same course (the 1D
  model has no roll mode and converges in a fraction of the time; its speed and power
  profile is most of the 3D solution away from corners). Only as a restart: as the
  first start it did not pay on verona-like with the issue-18 rider (448 iterations
  from the 1D plan against 301 cold, 2026-12-01);
- still capped: continue from the last iterate with IPOPT's acceptable level relaxed
  (`_RELAXED_TOL`: 1e-4 in 5 consecutive iterations), which the verification then
  has to confirm;
- converged but not verified (a speed the mesh does not resolve, e.g. a rider slowed
  far below the guess): the mesh is refined where the plan is slow
  (`mesh.speed_spacing_m` on the plan's own speeds and tyre forces), and re-solved (1D
  from the default guess, not from the invalid plan, which rides on the artefact; 3D
  from the plan), at most `_REFINE_ROUNDS` times; a 1D plan still invalid then gets the whole mesh at half the
  spacing (at 20 m intervals the 1D plans of bologna and rovereto-like came out
  invalid, 2026-12-01).

Boundary conditions (model.md section 5): upright on the centre line, `W_n = W_C/W_max`,
`E_n = 1`, end state free. Launch: the start speed is raised from `start_speed_mps` just
enough that the start power's tyre force uses at most `LAUNCH_GRIP` of the grip, which
keeps wet-road starts feasible (model.md, launch note).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.course.geometry import Course
from itt_planner.errors import SolveError
from itt_planner.ocp.mesh import build_mesh, road_data
from itt_planner.model.dynamics import (
    CONTROLS_3D,
    STATES_3D,
    ModelParams,
    SpatialModel,
    build_model,
    speed_bound_mps,
)
from itt_planner.ocp.guess import (
    LAUNCH_GRIP,
    PLAN_ARRAYS,
    V_MIN_MPS,
    initial_guess,
    plan_guess,
    plan_spacing_cap,
    speed_spacing_cap,
)
from itt_planner.ocp.plan import Plan
from itt_planner.model.rider import Rider
from itt_planner.ocp.solver import INVALID_RAW_STATUS, MU_MAX_1D, PlanStatus, full_course_options
from itt_planner.ocp.transcription import Transcription, transcribe
from itt_planner.ocp.verify import Verification, verify_plan
from itt_planner.model.wprime import WPrimeModel

log = logging.getLogger(__name__)

#: Bounds on the normalised rates u (model.md C13/C14 note: loose, for robustness).
U_DELTA_MAX = 20.0
U_W_MAX = 50.0
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
#: Share of the budget the first start may use (the rest is for the restarts).
_FIRST_SHARE = 0.6
#: IPOPT's acceptable tolerance of the relaxed restart (module docstring).
_RELAXED_TOL = 1e-4
#: Mesh refinements after a failed verification (module docstring).
_REFINE_ROUNDS = 2
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
        max_iter, max_cpu_time_s: the solver's budget for the whole solve (all
            restarts together); None (default) scales it with the course length
            (`budget`).
        tol: IPOPT's convergence tolerance.
        jit: compile the stage kernels to C with the machine's compiler (cached).
        verify: replay every plan (`verify.verify_plan`); off only for benchmarks of
            the solver alone.
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
    max_iter: int | None = None
    max_cpu_time_s: float | None = None
    tol: float = 1e-6
    jit: bool = True
    verify: bool = True

    def budget(self, model: str, length_m: float) -> tuple[int, float]:
        """(iterations, seconds) for one solve of `length_m` metres with `model`.

        Scaled with the course: 3D 500 iterations + 40 per km and 60 s + 10 s per km
        (the 17 km Bologna course needed ~500 iterations; measured times in
        bench/RESULTS.md), 1D 400 + 20 per km and 20 s + 2 s per km. The seconds are
        CPU seconds of this process (IPOPT's `max_cpu_time`, and the restarts' share):
        on a loaded, shared machine wall time says more about the neighbours than about
        the course.
        """
        km = max(length_m, 0.0) / 1000.0
        if model == "3d":
            iters, secs = 500 + 40 * km, 60.0 + 10.0 * km
        else:
            iters, secs = 400 + 20 * km, 20.0 + 2.0 * km
        return (int(self.max_iter if self.max_iter is not None else iters),
                float(self.max_cpu_time_s if self.max_cpu_time_s is not None else secs))


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


@lru_cache(maxsize=4)
def _transcription(kind: str, wprime_model: WPrimeModel, n_intervals: int, substeps: int,
                   jit: bool) -> Transcription:
    """The NLP of one node count (built once per process)."""
    return transcribe(_model(kind, wprime_model), n_intervals, substeps=substeps, compile_c=jit)


def _solver(tr: Transcription, *, max_iter: int, seconds: float, tol: float,
            bound_push: float, acceptable_tol: float | None = None) -> ca.Function:
    """An IPOPT solver over `tr` (cheap to build: the derivatives are `tr`'s)."""
    opts = {**tr.derivatives, **full_course_options(
        max_iter=max(int(max_iter), 1), max_cpu_time_s=max(seconds, 1.0), tol=tol,
        bound_push=bound_push, acceptable_tol=acceptable_tol,
        mu_max=MU_MAX_1D if tr.model.name == "1d" else None)}
    return ca.nlpsol(f"ocp_{tr.model.name}_{tr.layout.n_intervals}", "ipopt", tr.nlp, opts)


def start_speed(rider: Rider, conditions: Conditions, settings: OcpSettings) -> float:
    """Start speed: at least `start_speed_mps`, and enough for the start power's grip."""
    grip_force = LAUNCH_GRIP * conditions.mu_x * GRAVITY_MPS2 * rider.mass_kg
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


def bounds(model: SpatialModel, course: Course, nodes: np.ndarray, rider: Rider,
           settings: OcpSettings, x0: np.ndarray, conditions: Conditions = Conditions()
           ) -> tuple[np.ndarray, np.ndarray]:
    """Simple bounds on the states and controls per node (C11-C14, v_min <= v <= v_max).

    `v_max` is `model.speed_bound_mps` on the steepest descent of the course ahead: no
    physical ride gets faster, so it only keeps integration artefacts out (issue 18).
    """
    n = len(nodes)
    lbx = np.full((model.nx, n), -np.inf)
    ubx = np.full((model.nx, n), np.inf)
    lbx[model.index("v")] = V_MIN_MPS
    ahead = course.s_m >= nodes[0] - course.ds_m
    steepest = float(np.tan(np.min(course.beta_rad[ahead], initial=0.0)))
    ubx[model.index("v")] = speed_bound_mps(rider, conditions, steepest,
                                            start_mps=float(x0[model.index("v")]))
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


@dataclass
class _Problem:
    """One mesh's NLP with its numeric data: parameters, bounds, default guess."""

    tr: Transcription
    nodes: np.ndarray
    p: np.ndarray
    lbw: np.ndarray
    ubw: np.ndarray
    x_guess: np.ndarray
    u_guess: np.ndarray


@dataclass
class _Result:
    """One IPOPT run."""

    w: np.ndarray
    lam_g: np.ndarray
    objective: float
    status: str
    iterations: int


def _problem(course: Course, rider: Rider, conditions: Conditions, settings: OcpSettings,
             model: str, nodes: np.ndarray, v0: float, start: Start | None,
             guess: Plan | None) -> _Problem:
    substeps = substeps_for(float(np.max(np.diff(nodes)))) if model == "3d" else 1
    tr = _transcription(model, settings.wprime_model, len(nodes) - 1, substeps, settings.jit)
    spm = tr.model
    par = ModelParams(rider, conditions, settings.w_delta, settings.w_power).vector()
    x_guess, u_guess = initial_guess(spm, course, nodes, rider, conditions, v0)
    x0 = x_guess[:, 0].copy()
    if start is not None:
        for name, value in start.state.items():
            if name in spm.states:
                x0[spm.index(name)] = value
    if guess is not None:
        x_guess, u_guess = plan_guess(spm, guess, nodes, x_guess, u_guess)
    (lbx, ubx), (lbu, ubu) = bounds(spm, course, nodes, rider, settings, x0, conditions)
    if start is not None:
        # The guess's W' re-anchored at the start's: a rider off the plan has a deficit
        # (or a surplus) the whole rest of the guess would otherwise ignore.
        ie = spm.index("e_n")
        x_guess[ie] = x_guess[ie] - (x_guess[ie, 0] - lbx[ie, 0])
    x_guess[:, 0] = lbx[:, 0]
    lay = tr.layout
    return _Problem(tr, nodes, tr.params(road_data(course, nodes), par),
                    lay.join(lbx, lbu), lay.join(ubx, ubu), np.clip(x_guess, lbx, ubx), u_guess)


def _run(prob: _Problem, w0: np.ndarray, *, max_iter: int, seconds: float, tol: float,
         bound_push: float = _BOUND_PUSH, acceptable_tol: float | None = None) -> _Result:
    solver = _solver(prob.tr, max_iter=max_iter, seconds=seconds, tol=tol,
                     bound_push=bound_push, acceptable_tol=acceptable_tol)
    sol = solver(x0=np.clip(w0, prob.lbw, prob.ubw), p=prob.p, lbx=prob.lbw, ubx=prob.ubw,
                 lbg=prob.tr.lbg, ubg=prob.tr.ubg)
    stats = solver.stats()
    return _Result(np.asarray(sol["x"]).ravel(), np.asarray(sol["lam_g"]).ravel(),
                   float(sol["f"]), str(stats.get("return_status", "unknown")),
                   int(stats.get("iter_count", 0)))


def solve_plan(course: Course, rider: Rider, conditions: Conditions = Conditions(),
               settings: OcpSettings = OcpSettings(), *, model: str = "3d",
               guess: Plan | None = None, start: Start | None = None) -> Plan:
    """Solve the minimum-time OCP over the whole course, verify it, return the `Plan`.

    `start`: solve the rest of the course from a rider's state instead (the pacing
    engine's re-plan after the rider left the plan); the end conditions stay.

    `guess`: start IPOPT from this plan (any mesh, either model; `plan_guess`) instead
    of the default guess; the boundary conditions stay those of `rider`/`conditions`.
    Only the primal point is warm (a Plan keeps no multipliers), with the same IPOPT
    options as a cold solve (`mu_init` would not matter: the adaptive barrier update
    ignores it; measured identical). Measured on verona-like 3D, uniform 1 m mesh
    (16,800 nodes): cold, not converged in 400 iterations; from the non-uniform plan,
    converged in 687 iterations (642 s CPU).

    The restart strategies of the module docstring share one budget
    (`OcpSettings.budget`). A solve that does not converge, or whose plan fails its
    verification, still returns a Plan: `Plan.status` says which (`solver.PlanStatus`),
    `meta["success"]` is true only for a converged and verified plan, `meta["attempts"]`
    lists every IPOPT run and `meta["verification"]` the replay's figures.

    Raises:
        SolveError: unusable input (status "invalid_input"), e.g. a road narrower than the
            bike, or an unknown model name.
    """
    if model not in ("3d", "1d"):
        raise SolveError(f"unknown model {model!r}: choose '3d' or '1d'", status="invalid_input")
    check_inputs(course, rider, settings)
    t_start = time.perf_counter()
    cpu_start = time.process_time()
    start_m = 0.0 if start is None else start.s_m
    max_iter, seconds = settings.budget(model, course.length_m - start_m)
    h_max = settings.h_max_m if model == "3d" else settings.h_max_1d_m
    v0 = start_speed(rider, conditions, settings)
    if start is not None:
        v0 = float(start.state.get("v", v0))
    cap = speed_spacing_cap(course, rider, conditions, model, start_m, v0)
    if model == "3d":
        # 3D: a priori no finer than h_min_m. At 0.06 m launch intervals the hairpin took
        # 339 iterations (Restoration_Failed first) instead of 26 + 10 for a refinement
        # after the verification; the 1D model (no roll mode) gains from the fine launch:
        # 24 instead of 98 iterations on the 3.9 km climb of bench_convergence.
        cap = np.maximum(cap, settings.h_min_m)
    nodes = build_mesh(course, settings.h_min_m, h_max, settings.uniform_m, start_m=start_m,
                       h_cap_m=cap)
    prob = _problem(course, rider, conditions, settings, model, nodes, v0, start, guess)
    t_build = time.perf_counter() - t_start
    attempts: list[dict] = []

    def left() -> tuple[int, float]:
        used = sum(a["iterations"] for a in attempts)
        return max_iter - used, seconds - (time.process_time() - cpu_start)

    def run(strategy: str, pr: _Problem, w0: np.ndarray, share: float = 1.0,
            **kw: float) -> _Result:
        its, secs = left()
        its, secs = int(its * share), secs * share
        t0 = time.perf_counter()
        res = _run(pr, w0, max_iter=its, seconds=secs, tol=settings.tol, **kw)
        attempts.append({"strategy": strategy, "status": res.status,
                         "iterations": res.iterations, "n_nodes": len(pr.nodes),
                         "time_s": round(time.perf_counter() - t0, 3)})
        if PlanStatus.of(res.status) is not PlanStatus.CONVERGED:
            log.info("full-course %s OCP on %s, %s: %s after %d iterations", model,
                     course.name, strategy, res.status, res.iterations)
        return res

    def usable() -> bool:
        its, secs = left()
        return its > 10 and secs > 1.0

    lay = prob.tr.layout
    cold = lay.join(prob.x_guess, prob.u_guess)
    # The first start gets `_FIRST_SHARE` of the budget, so that a restart has some left.
    res = run("guess" if guess is not None else "cold", prob, cold, share=_FIRST_SHARE)
    if res.status in _RETRY_STATUSES and usable():
        res = run("smaller bound push", prob, cold, bound_push=_RETRY_BOUND_PUSH,
                  share=0.5)
    if PlanStatus.of(res.status) is not PlanStatus.CONVERGED and model == "1d" and usable():
        finer = build_mesh(course, settings.h_min_m, h_max / 2, None if settings.uniform_m
                           is None else settings.uniform_m / 2, start_m=start_m, h_cap_m=cap)
        prob = _problem(course, rider, conditions, settings, model, finer, v0, start, guess)
        lay = prob.tr.layout
        res = run("finer mesh", prob, lay.join(prob.x_guess, prob.u_guess), share=0.7)
    if (PlanStatus.of(res.status) is not PlanStatus.CONVERGED and model == "3d"
            and guess is None and usable()):
        _, secs = left()
        base = solve_plan(course, rider, conditions, dataclasses.replace(
            settings, max_iter=None, max_cpu_time_s=min(secs / 3, settings.budget(
                "1d", course.length_m - start_m)[1])), model="1d", start=start)
        attempts.append({"strategy": "1d plan for a warm start", "status": base.solver_status,
                         "iterations": base.iterations, "n_nodes": base.n_nodes,
                         "time_s": round(base.solve_time_s, 3)})
        if base.meta.get("success") and usable():
            warm = _problem(course, rider, conditions, settings, model, nodes, v0, start, base)
            res = run("warm from 1d", warm, lay.join(warm.x_guess, warm.u_guess))
    if PlanStatus.of(res.status) is PlanStatus.CAPPED and usable():
        res = run("relaxed tolerance", prob, res.w, bound_push=_RETRY_BOUND_PUSH,
                  acceptable_tol=_RELAXED_TOL)
    plan = _finish(prob, res, course, rider, conditions, settings, attempts)
    for _ in range(_REFINE_ROUNDS):
        if plan.status != PlanStatus.INVALID.value or not usable():
            break
        cap = np.minimum(cap, plan_spacing_cap(course, plan, rider, conditions))
        nodes = build_mesh(course, settings.h_min_m, h_max, settings.uniform_m,
                           start_m=start_m, h_cap_m=cap)
        if len(nodes) <= len(prob.nodes) * 1.001:
            break  # the plan's speeds ask for no finer mesh: the mismatch is not the step
        # 1D: from the default guess (or the caller's), not from the invalid plan, which
        # rides on the artefact the finer mesh removes (bologna at 20 m). 3D: from the
        # plan, whose mismatch was the launch (the hairpin from the default guess on the
        # refined mesh: Restoration_Failed after 340 iterations; from the plan: 10).
        prob = _problem(course, rider, conditions, settings, model, nodes, v0, start,
                        guess if model == "1d" else plan)
        res = run("refined where slow", prob, prob.tr.layout.join(prob.x_guess, prob.u_guess))
        plan = _finish(prob, res, course, rider, conditions, settings, attempts)
    if plan.status == PlanStatus.INVALID.value and model == "1d" and usable():
        # Still on an artefact: the whole mesh at half the spacing (bologna at 20 m).
        finer = build_mesh(course, settings.h_min_m, h_max / 2, None if settings.uniform_m
                           is None else settings.uniform_m / 2, start_m=start_m, h_cap_m=cap)
        prob = _problem(course, rider, conditions, settings, model, finer, v0, start, guess)
        res = run("finer mesh", prob, prob.tr.layout.join(prob.x_guess, prob.u_guess))
        plan = _finish(prob, res, course, rider, conditions, settings, attempts)
    if plan.status != PlanStatus.CONVERGED.value:
        log.warning("full-course %s OCP on %s: %s (%s) after %d iterations", model, course.name,
                    plan.status, plan.solver_status, plan.iterations)
    meta = {**plan.meta, "build_time_s": t_build,
            "budget": {"max_iter": max_iter, "seconds": seconds}}
    if start is not None:
        meta["start"] = {"s_m": start.s_m, "state": dict(start.state)}
    if guess is not None:
        meta["guess"] = {"model": guess.model, "n_nodes": guess.n_nodes,
                         "finish_time_s": guess.finish_time_s}
    return dataclasses.replace(plan, solve_time_s=time.perf_counter() - t_start, meta=meta)


def _finish(prob: _Problem, res: _Result, course: Course, rider: Rider, conditions: Conditions,
            settings: OcpSettings, attempts: list[dict]) -> Plan:
    """The plan of one IPOPT run, verified; its status and figures in `meta`."""
    status = PlanStatus.of(res.status)
    raw = res.status
    meta = {"course": course.name, "course_sha256": course.source_sha256,
            "rider": asdict(rider), "conditions": asdict(conditions),
            "settings": {k: (v.value if isinstance(v, WPrimeModel) else v)
                         for k, v in asdict(settings).items()},
            "objective": res.objective, "ipopt_status": raw, "attempts": list(attempts)}
    plan = to_plan(prob.tr, res.w, prob.p, res.lam_g, prob.nodes, rider, status=raw,
                   iterations=sum(a["iterations"] for a in attempts), solve_time_s=0.0,
                   meta=meta)
    check: Verification | None = None
    if settings.verify and np.all(np.isfinite(res.w)):
        substeps = substeps_for(float(np.max(np.diff(prob.nodes)))) if plan.model == "3d" else 1
        check = verify_plan(plan, course, rider, conditions, model=prob.tr.model,
                            substeps=substeps, wprime_model=settings.wprime_model)
        if status is PlanStatus.CONVERGED and not check.verified:
            status, raw = PlanStatus.INVALID, INVALID_RAW_STATUS
            log.warning("plan on %s is not verified: %s mismatch %.1fx its tolerance at "
                        "s = %.0f m", course.name, check.worst, check.worst_ratio,
                        check.worst_s_m)
    meta["verification"] = None if check is None else check.as_dict()
    meta["success"] = status is PlanStatus.CONVERGED
    return dataclasses.replace(plan, solver_status=raw, status=status.value, meta=meta)


def to_plan(tr: Transcription, w: np.ndarray, p: np.ndarray, lam_g: np.ndarray,
            nodes: np.ndarray, rider: Rider, *, status: str, iterations: int,
            solve_time_s: float, meta: dict) -> Plan:
    """Turn a numeric NLP solution (primal `w`, constraint multipliers `lam_g`) into a
    `Plan` (SI units, lateral arrays 0 for 1D); `status` is IPOPT's, `Plan.status` its
    class (`solver.PlanStatus.of`) until verification says otherwise."""
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
        solve_time_s=solve_time_s, meta=meta, status=PlanStatus.of(status).value,
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
    from itt_planner.model.rider import PRESETS  # noqa: PLC0415

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
