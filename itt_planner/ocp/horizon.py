"""The receding-horizon OCP: the 3D model over the next `H` metres from the rider's state.

`HorizonPlanner` builds ONE NLP (multiple shooting, `transcription.transcribe` with
`soft=True`, B's compiled per-stage derivative kernels) with a fixed number of intervals
and an IPOPT solver over it, once. A replan (`solve(state)`) only places that fixed
number of nodes over the window `[s, s + H]`, samples the road data there, sets bounds
and parameters, and calls the solver.

Design choices:

- Steady-lean horizon model (`model.build_3d_steady_lean`). The full-course plan keeps
  the full roll dynamics E4-E5; the horizon replaces them by their equilibrium, the
  steady turn `tan(phi) = -a_y/g` of E5. Why: the roll mode is an unstable pendulum
  with a ~0.45 s time constant, far below the ~1 s replan period and far below what
  the rider can be advised on; it only sets how fast the bike tips into a lean, which
  the steering-rate penalty and the rate bounds already keep physical. With the roll
  mode in the horizon, shooting intervals had to stay <= 4 m (longer ones span ~1 s of
  the instability and IPOPT needed huge Hessian regularisation), so a 1 km window
  needed >= 250 intervals and most replans on verona-like hit the caps (bench/
  bench/RESULTS.md). Without it, 5-20 m intervals are well conditioned. What the
  pacing depends on stays: the lean is still tied to the lateral acceleration, C16
  still bounds grip (hence the lean, `phi_max ~ atan(mu_y)`), and C15 still gates
  pedalling on that lean. Lost: the transient of initiating a lean (a few metres at
  corner entry), which the plan's solution already contains where it matters.
- Non-uniform window mesh with a fixed node count: nodes follow the full-course mesh
  density (`mesh.target_spacing`: fine where the road bends or the grade changes) and
  are also fine right ahead of the rider (what is advised now) and coarse towards the
  horizon end; a hairpin in the window gets ~2 m intervals, a straight up to `h_max_m`.
- Softened path constraints: the friction ellipse (C16) and the pedalling gate (C15)
  get penalised slacks, so a measured state that already violates them (GPS noise,
  a rider off the plan) never makes the NLP infeasible. Road edges (C11), W' >= 0 (C12)
  and the actuator bounds stay hard: the initial state is clipped into them, and since
  braking is always allowed (`W_n = -1` costs no W'), a feasible point exists - once
  the measured power is capped so that ramping it down to CP at the fastest allowed
  rate fits into the W' left (`initial_state`): a rider measured at W' = 0 far above CP
  otherwise made W' < 0 unavoidable in the first interval (seen near the finish).
- Terminal treatment: the rest of the course is represented by the full-course plan.
  The W' the rider may arrive with at the horizon end is the plan's W' there, shifted
  by the rider's current deviation from the plan scaled by the share of the remaining
  distance that lies beyond the horizon - a deficit (or surplus) is paid back (spent)
  evenly over what is left of the course, rather than within the next kilometre. It is
  a soft lower bound (slack with a steep penalty, ~45x a realistic W' price), so a W'
  deficit never makes the NLP infeasible, yet W' is not overspent for a seemingly
  faster horizon. The speed carried over the horizon end is worth time later: it is
  priced with the plan's costate there (`Plan.costate_v_s_per_mps`, d(finish time)/dv
  along the optimum: the first-order cost-to-go), plus a quadratic pull (`v_weight`) to
  the plan's speed. A quadratic pull alone has no slope at the plan's speed, so every
  window eased off towards its end to sell speed that costs ~1 s per m/s later; as the
  end moves on with every replan, the rider never eased off but rode 8-12 W over the
  plan up the verona-like climb and emptied W' 3.5 kJ early (bench/RESULTS.md).
- Corner speeds from the plan: where the plan corners at the grip limit, the horizon
  may not plan faster than the plan (`corner_speed_cap`): the steady-lean model below
  cannot know what leaning in costs.
- Warm start from the previous usable solution shifted in `s` (interpolated onto the
  new nodes, the plan beyond its end), re-anchored at the measured state; measured
  options in bench/RESULTS.md. An unusable iterate is never reused as a start:
  after a failed replan the next one again starts from the last usable solution, and
  only after `reset_after_failures` failures in a row from the plan.
- Two attempts within one budget: the warm attempt gets `warm_share` of the wall time;
  if its result is not usable, a cold attempt from the plan (larger barrier) gets the
  rest. A first replan (or one after a reset) is a single cold attempt with all of it.
- Real-time iteration idea, with IPOPT: an attempt stopped by the iteration or wall-time
  cap is still returned as success, status "Suboptimal_Feasible", when its iterate
  passes `feasible` - continuity gaps and bounds within `feasible_tol`, W' >= 0, grip
  and pedalling limits within `grip_tol`. Why: a trajectory that starts at the rider,
  obeys the dynamics, stays on the road, within grip and never empties W' below 0 is
  valid advice, while dropping it leaves the rider with older advice from a stale
  state. Measured on the verona-like sweep (bench/RESULTS.md, 6 such replans
  re-solved to convergence): window time +0.0 to +1.0 s of ~70 s, target power within
  18 W. The soft terminal W' target is not part of the check: one capped iterate was
  1.0 s faster than the optimum by ending its window 2.8 kJ below that target (W' still
  >= 0; the next replan, from the measured W', prices the deficit again).
  Capped iterates that are not yet feasible (open continuity gaps) are failures.
- Hard caps: `max_iter` and `max_wall_time_s` (per attempt, shared as above); a failure
  returns `success=False` with IPOPT's status per attempt and never raises.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.course.geometry import Course
from itt_planner.ocp.mesh import road_data, target_spacing
from itt_planner.model.dynamics import ModelParams, build_3d_steady_lean, speed_bound_mps, steady_lean_rad
from itt_planner.ocp.course_problem import U_DELTA_MAX, U_W_MAX
from itt_planner.ocp.guess import PLAN_ARRAYS, V_MIN_MPS, plan_spacing_cap
from itt_planner.ocp.plan import Plan
from itt_planner.model.rider import Rider
from itt_planner.ocp.solver import CAPPED_STATUSES, HORIZON_COLD, HORIZON_WARM, horizon_options
from itt_planner.model.state import RiderState
from itt_planner.ocp.transcription import transcribe

log = logging.getLogger(__name__)

#: IPOPT statuses of a run stopped by the budget, whose last iterate may still be usable.
_CAP_STATUSES = CAPPED_STATUSES
#: Status of a budget-capped iterate that passed `HorizonPlanner.feasible` (success=True).
SUBOPTIMAL_FEASIBLE = "Suboptimal_Feasible"
#: W' (as E_n) a usable iterate may undershoot 0 by: IPOPT's bound relaxation only.
_W_PRIME_TOL = 1e-6
#: Loose bound on the relative heading (rad), as in the full-course OCP.
_ALPHA_MAX_RAD = 1.0


@dataclass(frozen=True)
class HorizonSettings:
    """Size, terminal treatment and budgets of the receding-horizon OCP.

    Attributes:
        horizon_m: length of the window ahead of the rider.
        n_intervals: fixed number of shooting intervals over the window.
        substeps: RK4 substeps per interval.
        h_min_m, h_max_m: finest and coarsest window intervals (before the fixed node
            count rescales them).
        near_grade: how fast the spacing may grow with the distance ahead of the
            rider (m per m), so the first intervals (the advice now) are fine.
        slack_weight: penalty per unit of path-constraint slack (s).
        v_weight: terminal speed penalty (s per (m/s)^2).
        max_iter, max_wall_time_s: hard budget of one replan.
        tol: IPOPT tolerance (a replan needs less accuracy than the plan). 1e-4 since
            the NLP is unscaled: with 1e-3 the closed loop on the technical test course
            finished 1.3 % behind the optimum (tests/test_simulate.py), at the same
            iteration counts over the verona-like sweep.
        acceptable_iter: IPOPT stops after this many consecutive iterates within
            10 x `tol` ("Solved_To_Acceptable_Level", counted as success): the advice
            does not change measurably in the last digits, the latency ~2x.
        eps_wn, sharpness_w: smoothing widths of max(W_n, 0) and of the E9 switch at
            critical power (model.py) in the horizon model.
        w_delta, w_power: objective weights w_1, w_2 (model.md section 5).
        warm_multipliers: also shift the previous multipliers (measured neutral).
        margin_m: distance kept from each road edge (C11).
        feasible_tol: a budget-capped iterate is returned as success
            ("Suboptimal_Feasible") when its continuity gaps, bounds and path-constraint
            residuals are within this (state units: m, rad, m/s, E_n fractions).
        grip_tol: ... and its path-constraint slacks (grip C16, pedalling C15) within
            this beyond what the measured initial state already uses.
        warm_share: share of `max_wall_time_s` given to the warm attempt; the rest is
            the cold retry's (from the plan) when the warm attempt is not usable.
        reset_after_failures: after this many unusable replans in a row the last good
            solution is dropped and the next replan starts from the plan.
        corner_cap_use, corner_cap_tol_mps, corner_cap_brake_g: where the plan's friction
            use is at least `corner_cap_use`, the horizon's speed is capped at the plan's
            plus `corner_cap_tol_mps`, or what braking at `corner_cap_brake_g` g from the
            rider's speed reaches (`corner_speed_cap`).
    """

    horizon_m: float = 1000.0
    n_intervals: int = 60
    substeps: int = 1
    h_min_m: float = 2.5
    h_max_m: float = 30.0
    near_grade: float = 0.1
    slack_weight: float = 100.0
    v_weight: float = 1.0
    max_iter: int = 60
    max_wall_time_s: float = 0.8
    tol: float = 1e-4
    acceptable_iter: int = 2
    margin_m: float = 0.5
    eps_wn: float = 1e-3
    sharpness_w: float = 5.0
    w_delta: float = 0.01
    w_power: float = 0.01
    warm_multipliers: bool = False
    feasible_tol: float = 1e-3
    grip_tol: float = 0.02
    warm_share: float = 0.6
    reset_after_failures: int = 3
    corner_cap_use: float = 0.9
    corner_cap_tol_mps: float = 0.5
    corner_cap_brake_g: float = 0.3


@dataclass(frozen=True, eq=False)
class HorizonSolution:
    """One replan: profiles over the window (arc length `s_m` on the course, SI units).

    `t_s` starts at 0 at the rider's position. `phi_rad` is the steady lean of the
    horizon model. `predicted_finish_s` is the elapsed time from the ride start at the
    finish line: elapsed now + horizon time + the plan's time from the horizon end to
    the finish. `w_prime_finish_j` likewise adds the plan's W' change over the rest of
    the course.
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
        self._model = build_3d_steady_lean(eps_wn=settings.eps_wn,
                                           sharpness_w=settings.sharpness_w)
        # Without the transcription's acceleration bound (issue 18): the window never
        # starts below 1 m/s (`initial_state`), its spacing follows the plan's speed and
        # its speed is bounded by physics (`_speed_bound`); with the bound the technical-
        # descent sweep of test_horizon lost a usable replan (47 vs 48 of 50) and one
        # converged window broke grip at its first node.
        self._tr = transcribe(self._model, settings.n_intervals, substeps=settings.substeps,
                              soft=True, slack_weight=settings.slack_weight,
                              accel_bound=False)
        # Three solvers over the same NLP and derivative Functions (building is cheap):
        # the budget is an IPOPT option, so the warm attempt and the cold retry after
        # it get their shares of the wall time, a cold first start all of it.
        budget = settings.max_wall_time_s
        self._solvers = {
            kind: ca.nlpsol(f"horizon_{kind}", "ipopt", self._tr.nlp, {
                **self._tr.derivatives,
                **horizon_options(max_iter=settings.max_iter, max_wall_time_s=wall,
                                  tol=settings.tol, acceptable_iter=settings.acceptable_iter,
                                  start=start)})
            for kind, start, wall in (
                ("warm", HORIZON_WARM, settings.warm_share * budget),
                ("cold", HORIZON_COLD, budget),
                ("retry", HORIZON_COLD, (1.0 - settings.warm_share) * budget))}
        nlp = self._tr.nlp
        self._g = ca.Function("horizon_g", [nlp["x"], nlp["p"]], [nlp["g"]])
        self._par = ModelParams(rider, conditions, settings.w_delta, settings.w_power).vector()
        # Finer where the plan is slow (the launch): `dv/ds = a/v` is stiff there (issue 18).
        self._spacing = target_spacing(course, settings.h_min_m, settings.h_max_m,
                                       h_cap_m=plan_spacing_cap(course, plan, rider, conditions))
        self._previous: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._previous_mult: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._failures = 0

    @property
    def state_names(self) -> tuple[str, ...]:
        """Names of the rows of `initial_state` (the horizon model's states)."""
        return self._model.states

    # ---- window ---------------------------------------------------------------------------
    def window(self, s_m: float) -> np.ndarray:
        """The fixed-count node positions of the window starting at `s_m`.

        Equal steps of the cumulative node density `1/h`, with `h` the course's mesh
        spacing capped by `h_min_m + near_grade * (distance ahead)`. A window cut short
        by the finish has more nodes than that density asks for: the surplus is spread
        evenly (an added uniform density) instead of shrinking every interval alike,
        which left 0.85 m first intervals in a 150 m window, too short to steer from a
        measured line (a grip violation of 3x at the first node in test_horizon).
        """
        st, c = self.settings, self.course
        end = min(s_m + st.horizon_m, c.length_m)
        s_m = min(s_m, end - 1.0)
        grid = np.concatenate([[s_m], c.s_m[(c.s_m > s_m) & (c.s_m < end)], [end]])
        h = np.minimum(np.interp(grid, c.s_m, self._spacing),
                       st.h_min_m + st.near_grade * (grid - s_m))
        dens = 1.0 / h
        if end - s_m < st.horizon_m - 1.0:
            surplus = st.n_intervals - float(np.sum(0.5 * (dens[1:] + dens[:-1]) * np.diff(grid)))
            dens = dens + max(surplus, 0.0) / (end - s_m)
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(grid))])
        nodes = np.interp(np.linspace(0.0, cum[-1], st.n_intervals + 1), cum, grid)
        nodes[0], nodes[-1] = s_m, end
        return nodes

    def initial_state(self, state: RiderState, s_m: float) -> np.ndarray:
        """State vector of the horizon model from the estimate (steering: from the plan)."""
        r, m = self.rider, self._model
        x0 = np.zeros(m.nx)
        theta = float(self.course.at("theta_rad", s_m))
        heading = state.heading_rad if math.isfinite(state.heading_rad) else theta
        alpha = math.remainder(heading - theta, 2 * math.pi)
        v = max(float(state.speed_mps), 1.0) if math.isfinite(state.speed_mps) else 1.0
        power = float(state.power_w) if math.isfinite(state.power_w) else 0.0
        w_prime = float(np.clip(state.w_prime_j, 0.0, r.w_prime_j)) if math.isfinite(
            state.w_prime_j) else 0.0
        # Above CP, W' drains while the power ramps down at the fastest rate the NLP
        # allows (C13 with the E6 rate): (P - CP)^2 / (2 rate) must fit into the W' left,
        # or W' >= 0 (C12, a hard bound) makes the NLP infeasible - a rider measured at
        # W' = 0 while riding far above CP (the estimate says: exhausted) would get no
        # advice at all. Half of that margin covers the E9 smoothing and the RK4 step.
        rate_wps = r.power_rate_max_wps * U_W_MAX
        power = min(power, r.critical_power_w + math.sqrt(rate_wps * w_prime))
        # No more than the tyres transmit at this speed (C16, pedalling alone): a power
        # reading beyond it (a sprint measured at walking pace) would otherwise break the
        # transcription's acceleration bound in the first interval.
        power = min(power, self.conditions.mu_x * GRAVITY_MPS2 * r.mass_kg * v
                    / r.drivetrain_efficiency)
        if power >= 0:
            w_n = power / r.max_power_w
        else:
            w_n = power / (self.conditions.mu_x * GRAVITY_MPS2 * r.mass_kg * v)
        x0[m.index("n")] = state.n_m if math.isfinite(state.n_m) else 0.0
        x0[m.index("alpha")] = np.clip(alpha, -0.5, 0.5)
        x0[m.index("v")] = v
        x0[m.index("w_n")] = np.clip(w_n, -1.0, 1.0)
        x0[m.index("e_n")] = np.clip(w_prime / r.w_prime_j, 0.0, 1.0)
        x0[m.index("delta_n")] = self._plan_delta_n(np.array([s_m]))[0]
        return x0

    def _plan_delta_n(self, nodes: np.ndarray) -> np.ndarray:
        if self.plan.model == "3d":
            return self.plan.at("delta_n", nodes)
        # A 1D plan: the steering of the steady turn along the centre line.
        kappa = self.course.at("kappa_per_m", nodes)
        return np.arctan(self.rider.wheelbase_m * kappa) / self.rider.steer_max_rad

    def _plan_guess(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        m, plan = self._model, self.plan
        x = np.zeros((m.nx, len(nodes)))
        for name in ("n", "alpha", "v", "w_n", "e_n"):
            x[m.index(name)] = plan.at(PLAN_ARRAYS[name], nodes)
        x[m.index("delta_n")] = self._plan_delta_n(nodes)
        u = np.vstack([plan.at(PLAN_ARRAYS[name], nodes[:-1]) for name in ("u_delta", "u_w")])
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

    def _shift_multipliers(self, nodes: np.ndarray) -> dict[str, np.ndarray]:
        """The previous solution's multipliers moved onto `nodes` (zero beyond its end)."""
        if not self.settings.warm_multipliers or self._previous_mult is None:
            return {}
        s_prev, lam_x, lam_g = self._previous_mult
        lay = self._tr.layout
        inside = nodes <= s_prev[-1]

        def shift(rows: np.ndarray, s_from: np.ndarray, s_to: np.ndarray, keep: np.ndarray
                  ) -> np.ndarray:
            out = np.zeros((rows.shape[0], len(s_to)))
            for i in range(rows.shape[0]):
                out[i, keep] = np.interp(s_to[keep], s_from, rows[i])
            return out

        lx, lu, ls = lay.split(lam_x)
        lam_x_new = lay.join(shift(lx, s_prev, nodes, inside),
                             shift(lu, s_prev[:-1], nodes[:-1], inside[:-1]),
                             shift(ls, s_prev[:-1], nodes[:-1], inside[:-1]), lam_x[-1])
        lam_x_new[: lay.nx] = 0.0  # the first node is fixed by its bounds: no information
        n, nx, n_path = lay.n_intervals, lay.nx, lay.n_path
        gap = lam_g[: nx * n].reshape(n, nx).T
        path = lam_g[nx * n: nx * n + n_path * (n + 1)].reshape(n + 1, n_path).T
        lam_g_new = np.concatenate([
            shift(gap, s_prev[:-1], nodes[:-1], inside[:-1]).T.ravel(),
            shift(path, s_prev, nodes, inside).T.ravel(),
            # the acceleration bounds (transcription): inactive at a solution
            np.zeros(lay.accel_rows.stop - lay.accel_rows.start),
            lam_g[-1:]])
        return {"lam_x0": lam_x_new, "lam_g0": lam_g_new}

    def _bounds(self, nodes: np.ndarray, x0: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Simple bounds per node: C11-C14, v >= v_min; the first node fixed at `x0`."""
        m, c, n = self._model, self.course, len(nodes)
        lbx, ubx = np.full((m.nx, n), -np.inf), np.full((m.nx, n), np.inf)
        lbx[m.index("n")] = -(c.at("width_right_m", nodes) - self.settings.margin_m)  # C11
        ubx[m.index("n")] = c.at("width_left_m", nodes) - self.settings.margin_m
        lbx[m.index("alpha")], ubx[m.index("alpha")] = -_ALPHA_MAX_RAD, _ALPHA_MAX_RAD
        lbx[m.index("v")] = V_MIN_MPS
        ubx[m.index("v")] = np.minimum(self.corner_speed_cap(nodes, float(x0[m.index("v")])),
                                       self._speed_bound(nodes, float(x0[m.index("v")])))
        lbx[m.index("w_n")], ubx[m.index("w_n")] = -1.0, 1.0  # C13
        lbx[m.index("delta_n")], ubx[m.index("delta_n")] = -1.0, 1.0  # C14
        lbx[m.index("e_n")], ubx[m.index("e_n")] = 0.0, 1.0  # C12
        x0 = np.clip(x0, lbx[:, 0], ubx[:, 0])
        lbx[:, 0] = ubx[:, 0] = x0
        u_max = np.array([[U_DELTA_MAX], [U_W_MAX]])
        return lbx, ubx, np.repeat(-u_max, n - 1, axis=1), np.repeat(u_max, n - 1, axis=1)

    def _speed_bound(self, nodes: np.ndarray, v0: float) -> float:
        """Physics' upper speed bound over the window (`model.speed_bound_mps`, issue 18)."""
        c = self.course
        inside = (c.s_m >= nodes[0] - c.ds_m) & (c.s_m <= nodes[-1] + c.ds_m)
        steepest = float(np.tan(np.min(c.beta_rad[inside], initial=0.0)))
        return speed_bound_mps(self.rider, self.conditions, steepest, start_mps=v0)

    def corner_speed_cap(self, nodes: np.ndarray, v0: float) -> np.ndarray:
        """Upper speed bound per node: the plan's speed where the plan corners at the grip
        limit (friction use >= `corner_cap_use`), plus `corner_cap_tol_mps`.

        Why: there the speed is set by grip and by leaning in and out, and the plan,
        solved with the roll dynamics E4-E5, knows what that costs; the steady-lean
        horizon model does not (it tips into a lean at once), so on its own it planned
        braking later and entering tight corners 0.5-1 m/s faster than any rider can
        lean in, and a rider following that ran wide (bench/RESULTS.md). Elsewhere the
        speed stays free (pacing). The cap never asks for more than braking at
        `corner_cap_brake_g` g from the rider's speed gives (a rider measured too fast
        still has a feasible NLP).
        """
        st, plan = self.settings, self.plan
        cap = np.where(plan.at("friction_use", nodes) >= st.corner_cap_use,
                       plan.at("v_mps", nodes) + st.corner_cap_tol_mps, np.inf)
        reach = np.sqrt(np.maximum(
            v0 ** 2 - 2 * st.corner_cap_brake_g * GRAVITY_MPS2 * (nodes - nodes[0]), 0.0))
        return np.maximum(cap, np.maximum(reach, V_MIN_MPS))

    # ---- solve -------------------------------------------------------------------------------
    def solve(self, state: RiderState) -> HorizonSolution:
        """Replan from `state`. Never raises on solver failure: `success=False` + status."""
        t0 = time.perf_counter()
        st = self.settings
        s_est = float(state.s_m) if math.isfinite(state.s_m) else 0.0
        s0 = float(np.clip(s_est, 0.0, self.course.length_m - 1.0))
        nodes = self.window(s0)
        tr, lay, m = self._tr, self._tr.layout, self._model
        lbx, ubx, lbu, ubu = self._bounds(nodes, self.initial_state(state, s0))
        x0 = lbx[:, 0]
        end = nodes[-1]
        e_dev = x0[m.index("e_n")] - float(self.plan.at("e_n", s0))
        remaining = max(self.course.length_m - s0, 1.0)
        beyond = (self.course.length_m - end) / remaining
        e_target = float(self.plan.at("e_n", end)) + e_dev * beyond
        terminal = np.array([e_target, float(self.plan.at("v_mps", end)), st.v_weight,
                             float(self.plan.at("costate_v_s_per_mps", end))])
        p = tr.params(road_data(self.course, nodes), self._par, terminal)
        lbw = lay.join(lbx, lbu, np.zeros((lay.ns, lay.n_intervals)), 0.0)
        ubw = lay.join(ubx, ubu, np.full((lay.ns, lay.n_intervals), np.inf), np.inf)
        if self._failures >= st.reset_after_failures:
            self.reset()  # the last good solution is too far behind to be a good start
        x_guess, u_guess, start = self._guess(nodes)
        kinds = ("warm", "retry") if start == "shifted" else ("cold",)
        statuses, iterations = [], 0
        for kind in kinds:
            if kind == "retry":  # the plan re-anchored at the rider: a start from elsewhere
                x_guess, u_guess = self._plan_guess(nodes)
            if kind != "warm":  # re-anchor the plan's W' at the rider's (a W' deficit)
                ie = m.index("e_n")
                x_guess[ie] = np.clip(x_guess[ie] - (x_guess[ie, 0] - x0[ie]), 0.0, 1.0)
            x_guess[:, 0] = x0
            w0 = np.clip(lay.join(x_guess, u_guess), lbw, ubw)
            w, success, status, its, mult = self._attempt(kind, w0, p, lbw, ubw, nodes)
            iterations += its
            statuses.append(status)
            if success:
                break
            if its >= 1 and status in _CAP_STATUSES and self.feasible(w, p, lbw, ubw):
                success, status = True, SUBOPTIMAL_FEASIBLE
                statuses.append(status)
                break
        x, u, _ = lay.split(w)
        dt, y = (np.asarray(a) for a in tr.evaluate(w, p))
        t = np.concatenate([[0.0], np.cumsum(dt.ravel())])
        status = statuses[-1] if success else "; ".join(statuses)
        if success:
            self._failures = 0
            self._previous = (nodes, x, u)
            self._previous_mult = (nodes, *mult) if mult is not None else None
        else:
            self._failures += 1
            log.warning("horizon solve at s=%.0f m: %s after %d iterations", s0, status,
                        iterations)
        e_j = x[m.index("e_n")] * self.rider.w_prime_j
        plan_rest_t = self.plan.finish_time_s - float(self.plan.at("t_s", end))
        plan_rest_w = float(self.plan.w_prime_j[-1] - self.plan.at("w_prime_j", end))
        return HorizonSolution(
            s_m=nodes, n_m=x[m.index("n")], v_mps=x[m.index("v")], power_w=y[0],
            phi_rad=steady_lean_rad(y[2]), t_s=t, w_prime_j=e_j, success=success,
            status=status, iterations=iterations, solve_time_s=time.perf_counter() - t0,
            predicted_finish_s=state.elapsed_s + float(t[-1]) + plan_rest_t,
            w_prime_finish_j=float(e_j[-1]) + plan_rest_w)

    def _attempt(self, kind: str, w0: np.ndarray, p: np.ndarray, lbw: np.ndarray,
                 ubw: np.ndarray, nodes: np.ndarray
                 ) -> tuple[np.ndarray, bool, str, int, tuple[np.ndarray, np.ndarray] | None]:
        """One IPOPT run: (iterate, converged, status, iterations, multipliers)."""
        solver, tr = self._solvers[kind], self._tr
        try:
            sol = solver(x0=w0, p=p, lbx=lbw, ubx=ubw, lbg=tr.lbg, ubg=tr.ubg,
                         **(self._shift_multipliers(nodes) if kind == "warm" else {}))
        except RuntimeError as err:  # an evaluation error inside CasADi: report, never raise
            log.warning("horizon solve (%s) raised: %s", kind, err)
            return w0, False, f"error: {err}", 0, None
        stats = solver.stats()
        w = np.asarray(sol["x"]).ravel()
        if not np.all(np.isfinite(w)):
            return w0, False, "non-finite iterate", int(stats.get("iter_count", 0)), None
        return (w, bool(stats.get("success", False)), str(stats.get("return_status", "unknown")),
                int(stats.get("iter_count", 0)),
                (np.asarray(sol["lam_x"]).ravel(), np.asarray(sol["lam_g"]).ravel()))

    def feasible(self, w: np.ndarray, p: np.ndarray, lbw: np.ndarray, ubw: np.ndarray) -> bool:
        """Whether an iterate is valid advice: dynamics, road, grip and W' respected.

        The continuity gaps (E1-E9 integrated over each interval) and the simple bounds
        (road edges C11, W' >= 0 C12, actuators C13-C14) within `feasible_tol`, W' not
        below 0 beyond IPOPT's bound relaxation, and the path constraints themselves
        (grip C16, pedalling C15; their slacks only make the NLP solvable) within
        `grip_tol` of their limit or of what the measured initial state already uses.
        The soft terminal W' target is not checked: it is a price, not a safety limit.
        """
        st, lay = self.settings, self._tr.layout
        if np.any(w < lbw - st.feasible_tol) or np.any(w > ubw + st.feasible_tol):
            return False
        x, _, slacks = lay.split(w)
        if np.any(x[self._model.index("e_n")] < -_W_PRIME_TOL):
            return False
        g = np.asarray(self._g(w, p)).ravel()
        n_gap, n_path = lay.nx * lay.n_intervals, lay.n_path * lay.n_nodes
        if np.any(np.abs(g[:n_gap]) > st.feasible_tol):
            return False
        # g_path = path - slack per node (the final node shares the last stage's slacks).
        path = g[n_gap: n_gap + n_path].reshape(lay.n_nodes, lay.n_path).T
        if slacks.size:
            path = path + np.hstack([slacks, slacks[:, -1:]])
        allowed = np.maximum(path[:, :1], 0.0) + st.grip_tol
        return bool(np.all(path <= allowed))

    def reset(self) -> None:
        """Forget the warm start (e.g. after a jump of the estimate)."""
        self._previous = None
        self._previous_mult = None
        self._failures = 0
