"""The receding-horizon OCP: the 3D model over the next `H` metres from the rider's state.

`HorizonPlanner` builds ONE NLP (multiple shooting, `transcription.transcribe` with
`soft=True`) with a fixed number of intervals and an IPOPT solver over it, once. A replan
(`solve(state)`) only samples the road data for the window `[s, s + H]` on a mesh of that
fixed node count (nodes placed with the density of `mesh.target_spacing`, so a hairpin
in the window gets ~1 m intervals), sets the bounds and parameters, and calls the solver.

Design choices:

- Softened path constraints: the friction ellipse (C16) and the pedalling gate (C15)
  get penalised slacks, so a measured state that already violates them (GPS noise,
  a rider off the plan) never makes the NLP infeasible. Road edges (C11), W' >= 0 (C12)
  and the actuator bounds stay hard: the initial state is clipped into them.
- Terminal treatment: the rest of the course is represented by the full-course plan.
  The W' the rider may arrive with at the horizon end is the plan's W' there, shifted
  by the rider's current deviation from the plan scaled by the share of the remaining
  distance that lies beyond the horizon - a deficit (or surplus) is paid back (spent)
  evenly over what is left of the course, rather than within the next kilometre. It is
  a soft lower bound with a steep penalty (~45x a realistic W' price), so W' is never
  overspent for a seemingly faster horizon. The speed at the horizon end is pulled to
  the plan's speed there (quadratic, `v_weight`), because kinetic energy carried over
  the horizon end is worth time later; without it the horizon would coast to a crawl
  at its end. The W' price alone (without the bound) was rejected: a linear price
  cannot stop the solver from emptying W' whenever the horizon gains more than it.
- Warm start from the previous successful solution shifted in `s` (interpolated onto
  the new nodes, the plan beyond its end); primal only - the prototype found
  multiplier warm starts worse. A failed solution is never reused as a start.
- Hard caps: `max_iter` and `max_wall_time_s`; a failure returns `success=False` with
  IPOPT's status and never raises.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from itt_planner.conditions import GRAVITY_MPS2, Conditions
from itt_planner.course import Course
from itt_planner.mesh import road_data, target_spacing
from itt_planner.model import ModelParams, build_3d
from itt_planner.ocp import V_MIN_MPS, OcpSettings, bounds
from itt_planner.plan import Plan
from itt_planner.rider import Rider
from itt_planner.state import RiderState
from itt_planner.transcription import transcribe

log = logging.getLogger(__name__)

#: The start point (plan or shifted previous solution) is close to the optimum: begin
#: with a small barrier parameter and keep the start inside the bounds it already
#: satisfies, instead of IPOPT's defaults for a cold start far away.
_WARM_IPOPT = {"mu_init": 1e-3, "warm_start_init_point": "yes", "warm_start_bound_push": 1e-6,
               "warm_start_mult_bound_push": 1e-6, "mu_strategy": "monotone"}


@dataclass(frozen=True)
class HorizonSettings:
    """Size, terminal treatment and budgets of the receding-horizon OCP.

    Attributes:
        horizon_m: length of the window ahead of the rider.
        n_intervals: fixed number of shooting intervals over the window.
        substeps: RK4 substeps per interval (intervals stay near 5 m on straights).
        h_min_m, h_max_m: mesh density bounds (as in the full-course mesh).
        slack_weight: penalty per unit of path-constraint slack (s).
        v_weight: terminal speed penalty (s per (m/s)^2).
        max_iter, max_wall_time_s: hard budget of one replan.
        tol: IPOPT tolerance (a replan needs less accuracy than the plan).
        margin_m: distance kept from each road edge (C11).
    """

    horizon_m: float = 1000.0
    n_intervals: int = 200
    substeps: int = 1
    h_min_m: float = 1.0
    h_max_m: float = 4.0
    slack_weight: float = 100.0
    v_weight: float = 1.0
    max_iter: int = 60
    max_wall_time_s: float = 0.8
    tol: float = 1e-4
    margin_m: float = 0.5


@dataclass(frozen=True, eq=False)
class HorizonSolution:
    """One replan: profiles over the window (arc length `s_m` on the course, SI units).

    `t_s` starts at 0 at the rider's position. `predicted_finish_s` is the elapsed time
    from the ride start at the finish line: elapsed now + horizon time + the plan's time
    from the horizon end to the finish. `w_prime_finish_j` likewise adds the plan's W'
    change over the rest of the course.
    """

    s_m: np.ndarray
    n_m: np.ndarray
    v_mps: np.ndarray
    power_w: np.ndarray
    phi_rad: np.ndarray
    t_s: np.ndarray
    w_prime_j: np.ndarray
    success: bool
    status: str
    iterations: int
    solve_time_s: float
    predicted_finish_s: float
    w_prime_finish_j: float

    @property
    def target_power_w(self) -> float:
        """Power to ride now: the first interval's end (the start holds the measured one)."""
        return float(self.power_w[1])


class HorizonPlanner:
    """Receding-horizon OCP built once; `solve(state)` many times (never raises)."""

    def __init__(self, course: Course, rider: Rider, plan: Plan,
                 conditions: Conditions = Conditions(),
                 settings: HorizonSettings = HorizonSettings()) -> None:
        self.course, self.rider, self.plan = course, rider, plan
        self.conditions, self.settings = conditions, settings
        self._model = build_3d()
        self._tr = transcribe(self._model, settings.n_intervals, substeps=settings.substeps,
                              soft=True, slack_weight=settings.slack_weight)
        opts = {**self._tr.derivatives,
                "ipopt.max_iter": settings.max_iter, "ipopt.max_wall_time": settings.max_wall_time_s,
                "ipopt.tol": settings.tol, "ipopt.acceptable_tol": 10 * settings.tol,
                "ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
                "ipopt.linear_solver": "mumps",
                "error_on_fail": False, "no_nlp_grad": True, "calc_lam_p": False,
                **{f"ipopt.{k}": v for k, v in _WARM_IPOPT.items()}}
        self._solver = ca.nlpsol("horizon", "ipopt", self._tr.nlp, opts)
        self._par = ModelParams(rider, conditions).vector()
        # Cumulative node density along the course: equal steps of it give the window mesh.
        density = 1.0 / target_spacing(course, settings.h_min_m, settings.h_max_m)
        self._density_cum = np.concatenate([[0.0], np.cumsum(
            0.5 * (density[1:] + density[:-1]) * np.diff(course.s_m))])
        self._ocp_settings = OcpSettings(margin_m=settings.margin_m)
        self._previous: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    # ---- window ---------------------------------------------------------------------------
    def window(self, s_m: float) -> np.ndarray:
        """The fixed-count node positions of the window starting at `s_m`."""
        end = min(s_m + self.settings.horizon_m, self.course.length_m)
        s_m = min(s_m, end - 1.0)
        c0, c1 = np.interp([s_m, end], self.course.s_m, self._density_cum)
        # Blend with a uniform spacing so straights are not starved of nodes entirely.
        c = np.linspace(0.0, 1.0, self.settings.n_intervals + 1)
        s_dense = np.interp(c0 + c * (c1 - c0), self._density_cum, self.course.s_m)
        nodes = 0.7 * s_dense + 0.3 * (s_m + c * (end - s_m))
        nodes[0], nodes[-1] = s_m, end
        return nodes

    def initial_state(self, state: RiderState, s_m: float) -> np.ndarray:
        """State vector of the 3D model from the estimate (roll, steering: from the plan)."""
        r, m = self.rider, self._model
        x0 = np.zeros(m.nx)
        theta = float(self.course.at("theta_rad", s_m))
        alpha = math.remainder(state.heading_rad - theta, 2 * math.pi)
        v = max(float(state.speed_mps), 1.0) if math.isfinite(state.speed_mps) else 1.0
        power = float(state.power_w) if math.isfinite(state.power_w) else 0.0
        if power >= 0:
            w_n = power / r.max_power_w
        else:
            w_n = power / (self.conditions.mu_x * GRAVITY_MPS2 * r.mass_kg * v)
        x0[m.index("n")] = state.n_m
        x0[m.index("alpha")] = np.clip(alpha, -0.5, 0.5)
        x0[m.index("v")] = v
        x0[m.index("w_n")] = np.clip(w_n, -1.0, 1.0)
        x0[m.index("e_n")] = np.clip(state.w_prime_j / r.w_prime_j, 0.0, 1.0)
        if self.plan.model == "3d":
            for name, attr in (("phi", "phi_rad"), ("phi_dot", "phi_dot_radps"),
                               ("delta_n", "delta_n")):
                x0[m.index(name)] = float(self.plan.at(attr, s_m))
        return x0

    def _plan_guess(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        m, plan = self._model, self.plan
        x = np.vstack([plan.at(attr, nodes) for attr in (
            "n_m", "alpha_rad", "phi_rad", "phi_dot_radps", "v_mps", "w_n", "delta_n", "e_n")])
        u = np.vstack([plan.at("u_delta", nodes[:-1]), plan.at("u_w", nodes[:-1])])
        if plan.model != "3d":  # a 1D plan: steady lean and steering on the centre line
            kappa = self.course.at("kappa_per_m", nodes)
            x[m.index("delta_n")] = np.arctan(self.rider.wheelbase_m * kappa) / self.rider.steer_max_rad
            x[m.index("phi")] = -np.arctan(x[m.index("v")] ** 2 * kappa / GRAVITY_MPS2)
        return x, u

    def _guess(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray, str]:
        x, u = self._plan_guess(nodes)
        if self._previous is None:
            return x, u, "plan"
        s_prev, x_prev, u_prev = self._previous
        inside = nodes <= s_prev[-1]
        if not np.any(inside[1:]):
            return x, u, "plan"
        for i in range(x.shape[0]):
            x[i, inside] = np.interp(nodes[inside], s_prev, x_prev[i])
        inside_u = inside[:-1]
        for i in range(u.shape[0]):
            u[i, inside_u] = np.interp(nodes[:-1][inside_u], s_prev[:-1], u_prev[i])
        return x, u, "shifted"

    # ---- solve -------------------------------------------------------------------------------
    def solve(self, state: RiderState) -> HorizonSolution:
        """Replan from `state`. Never raises on solver failure: `success=False` + status."""
        t0 = time.perf_counter()
        s0 = float(np.clip(state.s_m, 0.0, self.course.length_m - 1.0))
        nodes = self.window(s0)
        tr, lay, m = self._tr, self._tr.layout, self._model
        (lbx, ubx), (lbu, ubu) = bounds(m, self.course, nodes, self.rider,
                                        self._ocp_settings, np.zeros(m.nx))
        x0 = self.initial_state(state, s0)
        x0 = np.clip(x0, np.where(np.isfinite(lbx[:, 1]), lbx[:, 1], -1e9),
                     np.where(np.isfinite(ubx[:, 1]), ubx[:, 1], 1e9))
        x0[m.index("v")] = max(x0[m.index("v")], V_MIN_MPS)
        lbx[:, 0] = ubx[:, 0] = x0
        x_guess, u_guess, _ = self._guess(nodes)
        x_guess[:, 0] = x0
        end = nodes[-1]
        e_dev = x0[m.index("e_n")] - float(self.plan.at("e_n", s0))
        remaining = max(self.course.length_m - s0, 1.0)
        e_target = float(self.plan.at("e_n", end)) + e_dev * (self.course.length_m - end) / remaining
        terminal = np.array([e_target, float(self.plan.at("v_mps", end)), self.settings.v_weight])
        p = tr.params(road_data(self.course, nodes), self._par, terminal)
        lbw = lay.join(lbx, lbu, np.zeros((lay.ns, lay.n_intervals)), 0.0)
        ubw = lay.join(ubx, ubu, np.full((lay.ns, lay.n_intervals), np.inf), np.inf)
        w0 = np.clip(lay.join(x_guess, u_guess), lbw, ubw)
        try:
            sol = self._solver(x0=w0, p=p, lbx=lbw, ubx=ubw, lbg=tr.lbg, ubg=tr.ubg)
            stats = self._solver.stats()
            w = np.asarray(sol["x"]).ravel()
            success = bool(stats.get("success", False)) and np.all(np.isfinite(w))
            status = str(stats.get("return_status", "unknown"))
            iterations = int(stats.get("iter_count", 0))
        except RuntimeError as err:  # an evaluation error inside CasADi: report, never raise
            log.warning("horizon solve at s=%.0f m raised: %s", s0, err)
            w, success, status, iterations = w0, False, f"error: {err}", 0
        x, u, _ = lay.split(w)
        dt, y = (np.asarray(a) for a in tr.evaluate(w, p))
        t = np.concatenate([[0.0], np.cumsum(dt.ravel())])
        if success:
            self._previous = (nodes, x, u)
        else:
            log.warning("horizon solve at s=%.0f m: %s after %d iterations", s0, status,
                        iterations)
        e_j = x[m.index("e_n")] * self.rider.w_prime_j
        plan_rest_t = self.plan.finish_time_s - float(self.plan.at("t_s", end))
        plan_rest_w = float(self.plan.w_prime_j[-1] - self.plan.at("w_prime_j", end))
        return HorizonSolution(
            s_m=nodes, n_m=x[m.index("n")], v_mps=x[m.index("v")], power_w=y[0],
            phi_rad=x[m.index("phi")], t_s=t, w_prime_j=e_j, success=success, status=status,
            iterations=iterations, solve_time_s=time.perf_counter() - t0,
            predicted_finish_s=state.elapsed_s + float(t[-1]) + plan_rest_t,
            w_prime_finish_j=float(e_j[-1]) + plan_rest_w)

    def reset(self) -> None:
        """Forget the warm start (e.g. after a jump of the estimate)."""
        self._previous = None
