"""The full-course OCP on one mesh: its NLP and numeric data, and a solution as a `Plan`.

`course_nlp` builds what one solver run needs (model.md section 5): the transcription
of the model over the mesh's node count (direct multiple shooting with RK4,
`transcription.transcribe`; built and compiled once per node count and process), the
parameter vector (road data per interval, the rider and the conditions), the simple
bounds C11-C14 (`bounds.simple_bounds`, shared with the receding horizon) and a
physically sensible guess (`guess.initial_guess`, or an existing plan moved onto the
mesh, `guess.plan_guess`). `to_plan` turns a solver's iterate into a `Plan`.

Boundary conditions: upright on the centre line, `W_n = W_C/W_max`, `E_n = 1`, end state
free (or the rider's state at a `Start`). Launch: the start speed is raised from
`start_speed_mps` just enough that the start power's tyre force uses at most
`LAUNCH_GRIP` of the grip, which keeps wet-road starts feasible (model.md, launch note).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.errors import SolveError
from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.dynamics import CONTROLS_3D, STATES_3D, SpatialModel, build_model
from itt_planner.model.params import ModelParams
from itt_planner.model.rider import Rider
from itt_planner.model.wprime import WPrimeModel
from itt_planner.ocp.bounds import V_MIN_MPS, simple_bounds, speed_limit_mps
from itt_planner.ocp.course_settings import OcpSettings, Start
from itt_planner.ocp.guess import (
    LAUNCH_GRIP,
    PLAN_ARRAYS,
    initial_guess,
    plan_guess,
    plan_rows,
)
from itt_planner.ocp.mesh import road_data
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import PlanStatus, SolveResult
from itt_planner.ocp.transcription import Layout, Transcription, layout_of, transcribe

#: Interval length (m) above which the RK4 integrator takes several substeps.
_SUBSTEP_M = 4.0


def substeps_for(h_max_m: float) -> int:
    """RK4 substeps so that no substep exceeds `_SUBSTEP_M` (roll time constant ~0.45 s)."""
    return max(1, math.ceil(h_max_m / _SUBSTEP_M - 1e-9))


def mesh_substeps(model: str, nodes: np.ndarray) -> int:
    """RK4 substeps of `model` on the mesh `nodes` (the 1D model has no roll mode: 1)."""
    return substeps_for(float(np.max(np.diff(nodes)))) if model == "3d" else 1


@lru_cache(maxsize=16)
def spatial_model(kind: str, wprime_model: WPrimeModel) -> SpatialModel:
    """The model `kind` ("3d" or "1d") with `wprime_model` (built once per process)."""
    return build_model(kind, wprime_model)


@lru_cache(maxsize=4)
def _transcription(kind: str, wprime_model: WPrimeModel, n_intervals: int, substeps: int,
                   jit: bool) -> Transcription:
    """The NLP of one node count (built once per process)."""
    return transcribe(spatial_model(kind, wprime_model), n_intervals, substeps=substeps,
                      compile_c=jit)


def course_layout(kind: str, wprime_model: WPrimeModel, n_intervals: int) -> Layout:
    """The layout of the full-course NLP (`_transcription`'s) on `n_intervals`, without
    building it: what a primal-dual point of that NLP must fit."""
    return layout_of(spatial_model(kind, wprime_model), n_intervals)


def start_speed(rider: Rider, conditions: Conditions, settings: OcpSettings) -> float:
    """Start speed: at least `start_speed_mps`, and enough for the start power's grip."""
    grip_force = LAUNCH_GRIP * conditions.mu_x * GRAVITY_MPS2 * rider.mass_kg
    return max(settings.start_speed_mps, rider.critical_power_w / grip_force, V_MIN_MPS)


def check_inputs(course: Course, settings: OcpSettings) -> None:
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


@dataclass(frozen=True, eq=False)
class CourseNlp:
    """One mesh's NLP with its numeric data: parameters, bounds, default guess."""

    tr: Transcription
    nodes: np.ndarray
    p: np.ndarray
    lbw: np.ndarray
    ubw: np.ndarray
    x_guess: np.ndarray
    u_guess: np.ndarray

    @property
    def w_guess(self) -> np.ndarray:
        """The guess as a decision vector."""
        return self.tr.layout.join(self.x_guess, self.u_guess)


def course_nlp(course: Course, rider: Rider, conditions: Conditions, settings: OcpSettings,
               model: str, nodes: np.ndarray, v0: float, start: Start | None,
               guess: Plan | None, free_start: Sequence[str] = ()) -> CourseNlp:
    """The NLP of `model` on the mesh `nodes`, launched at `v0` (or from `start`), with
    the default guess or `guess` moved onto the mesh. `free_start`: states of a `start`
    left to the solver within their simple bounds (the start's value is only their
    guess): what the rider's estimate does not measure (`course_replan.start_from`)."""
    tr = _transcription(model, settings.wprime_model, len(nodes) - 1,
                        mesh_substeps(model, nodes), settings.jit)
    spm = tr.model
    par = ModelParams(rider, conditions, settings.w_delta, settings.w_power).vector()
    if (guess is not None and start is not None
            and set(spm.states) <= set(start.state)
            and set(spm.states + spm.controls) <= plan_rows(guess)):
        # A re-solve of the rest from a plan of its model: the plan and the start give
        # every row, so the default guess would be overwritten whole (the 3D's cost
        # 1.1 s of a warm 1-12 s re-solve on the Zwift Bologna ride, a fifth of them all).
        x_guess, u_guess = np.zeros((spm.nx, len(nodes))), np.zeros((spm.nu, len(nodes) - 1))
    else:
        x_guess, u_guess = initial_guess(spm, course, nodes, rider, conditions, v0)
    x0 = x_guess[:, 0].copy()
    if start is not None:
        for name, value in start.state.items():
            if name in spm.states:
                x0[spm.index(name)] = value
    if guess is not None:
        x_guess, u_guess = plan_guess(spm, guess, nodes, x_guess, u_guess)
    v_max = speed_limit_mps(course, nodes, rider, conditions, float(x0[spm.index("v")]))
    bounds = simple_bounds(spm, course, nodes, x0, margin_m=settings.margin_m,
                           v_max_mps=v_max, finish_mu_y=conditions.mu_y,
                           e_final_min=settings.e_final_min)
    lbx, ubx = bounds.lbx, bounds.ubx
    if start is not None:
        # The guess's W' re-anchored at the start's: a rider off the plan has a deficit
        # (or a surplus) the whole rest of the guess would otherwise ignore.
        ie = spm.index("e_n")
        x_guess[ie] = x_guess[ie] - (x_guess[ie, 0] - lbx[ie, 0])
    x_guess[:, 0] = lbx[:, 0]
    if start is not None:
        for name in free_start:
            if name in spm.states:  # the bounds of any other node
                i = spm.index(name)
                lbx[i, 0], ubx[i, 0] = lbx[i, 1], ubx[i, 1]
    lbw, ubw = bounds.decision(tr.layout)
    return CourseNlp(tr, nodes, tr.params(road_data(course, nodes), par), lbw, ubw,
                     np.clip(x_guess, lbx, ubx), u_guess)


@dataclass(frozen=True, eq=False)
class PrimalDual:
    """A converged run's primal-dual point on its mesh: what a re-solve of the rest of
    the course starts from, on the same mesh cut at the rider (`cut_nodes`, `cut_point`).

    Why: a full-course plan is the optimum of the rest of the course from any of its own
    states (Bellman), so a rider a little off it is a small perturbation of that
    optimum; from the primal point alone IPOPT spent 40-120 iterations finding the
    active arcs (C11 on the inside edges, C15, C16, W' = 0) again (bench/RESULTS.md,
    2026-12-01, issue 14 re-solves), as the capped 3D runs did before they resumed with
    their multipliers (H5: 4-73 iterations).
    """

    nodes: np.ndarray
    w: np.ndarray
    lam_x: np.ndarray
    lam_g: np.ndarray


def cut_nodes(nodes: np.ndarray, s0_m: float, min_first_m: float, grid_s_m: np.ndarray,
              h_cap_m: np.ndarray) -> np.ndarray:
    """`nodes` from `s0_m` on: `s0_m`, then the nodes more than `min_first_m` beyond
    it, each interval longer than the spacing cap `h_cap_m` (on `grid_s_m`) where it
    starts split into equal parts (a rider slower than the plan needs a finer launch:
    `guess.speed_spacing_cap`)."""
    cut = np.concatenate([[s0_m], nodes[np.searchsorted(nodes, s0_m + min_first_m,
                                                        side="right"):]])
    h_cap = np.interp(cut[:-1], grid_s_m, h_cap_m)
    parts = np.maximum(np.ceil(np.diff(cut) / h_cap - 1e-9), 1).astype(int)
    inner = [np.linspace(a, b, m, endpoint=False)[1:]
             for a, b, m in zip(cut[:-1], cut[1:], parts, strict=True) if m > 1]
    return np.sort(np.concatenate([cut, *inner]))


def cut_point(tr: Transcription, point: PrimalDual, nodes: np.ndarray, x0: np.ndarray
              ) -> SolveResult:
    """`point` moved onto `nodes` (`cut_nodes`: the old nodes from the start on, some
    intervals split) for the NLP `tr`, node 0 at `x0`, as a resumable run (`SolveResult`
    with its multipliers). States are interpolated in s; a new interval takes the
    controls and the gap and acceleration multipliers of the old interval holding its
    midpoint (the costate is continuous), a new node the bound and path multipliers of
    the nearest old node: on the old nodes themselves the point is the old one."""
    lay = tr.layout
    old = dataclasses.replace(lay, n_intervals=len(point.nodes) - 1)
    mid = 0.5 * (nodes[1:] + nodes[:-1])
    held = np.clip(np.searchsorted(point.nodes, mid, side="right") - 1, 0, old.n_intervals - 1)
    near = np.clip(np.searchsorted(point.nodes, nodes), 1, old.n_intervals)
    near = np.where(np.abs(point.nodes[near - 1] - nodes) < np.abs(point.nodes[near] - nodes),
                    near - 1, near)

    def vector(v: np.ndarray, interpolate: bool) -> np.ndarray:
        x, u, _ = old.split(v)
        xs = (np.array([np.interp(nodes, point.nodes, row) for row in x]) if interpolate
              else x[:, near])
        return lay.join(xs, u[:, held])

    w = vector(point.w, True)
    w[: lay.nx] = x0
    g = point.lam_g
    gaps = g[: old.n_gap].reshape(old.n_intervals, old.nx)[held]
    path = g[old.n_gap: old.n_gap + old.n_path * old.n_nodes].reshape(old.n_nodes, old.n_path)
    accel = g[old.accel_rows]
    lam_g = np.concatenate([gaps.ravel(), path[near].ravel(),
                            accel[held] if len(accel) else accel])
    return SolveResult(w, vector(point.lam_x, False), lam_g, float("nan"),
                       PlanStatus.CONVERGED, "cut", 0, 0.0)


def to_plan(tr: Transcription, w: np.ndarray, p: np.ndarray, lam_g: np.ndarray,
            nodes: np.ndarray, rider: Rider, *, status: str, iterations: int,
            solve_time_s: float, meta: dict[str, Any]) -> Plan:
    """Turn a numeric NLP solution (primal `w`, constraint multipliers `lam_g`) into a
    `Plan` (SI units, lateral arrays 0 for 1D); `status` is the solver's raw status,
    `Plan.status` its class (`solver.PlanStatus.of`) until verification says otherwise."""
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
