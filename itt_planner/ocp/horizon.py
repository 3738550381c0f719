"""The receding-horizon OCP: the 3D model over the next `H` metres from the rider's state.

`HorizonPlanner` builds ONE NLP (multiple shooting, `transcription.transcribe` with
`soft=True`, B's compiled per-stage derivative kernels) with a fixed number of intervals
and its solvers over it (`solver.horizon_solver`, the solver seam), once. A replan
(`solve(state)`) only places that fixed number of nodes over the window `[s, s + H]`,
samples the road data there, sets bounds and parameters (`horizon_window`), and calls
a solver. Settings and the returned solution: `horizon_settings`.

Design choices:

- Steady-lean horizon model (`model.build_3d_steady_lean`). The full-course plan keeps
  the full roll dynamics E4-E5; the horizon replaces them by their equilibrium, the
  steady turn `tan(phi) = -a_y/g` of E5. Why: the roll mode is an unstable pendulum
  with a ~0.45 s time constant, far below the ~1 s replan period and far below what
  the rider can be advised on; it only sets how fast the bike tips into a lean, which
  the steering-rate penalty and the rate bounds already keep physical. With the roll
  mode in the horizon, shooting intervals had to stay <= 4 m (longer ones span ~1 s of
  the instability and IPOPT needed huge Hessian regularisation), so a 1 km window
  needed >= 250 intervals and most replans on verona-like hit the caps
  (bench/RESULTS.md). Without it, 5-20 m intervals are well conditioned. What the
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
  by the rider's current deviation from the plan (carried to the horizon end through
  E9 along the plan's power, `HorizonWindow.terminal_e_n`: a deviation added as it is
  could ask for more than full W') scaled by the share of the remaining distance that
  lies beyond the horizon - a deficit (or surplus) is paid back (spent)
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
- Real-time iteration idea: an attempt stopped by the iteration or wall-time cap
  (`PlanStatus.CAPPED`) is still returned as success, status "Suboptimal_Feasible"
  (`outcome` capped), when its iterate
  passes `HorizonNlp.feasible` - continuity gaps and bounds within `feasible_tol`, W' >= 0, grip
  and pedalling limits within `grip_tol`. Why: a trajectory that starts at the rider,
  obeys the dynamics, stays on the road, within grip and never empties W' below 0 is
  valid advice, while dropping it leaves the rider with older advice from a stale
  state. Measured on the verona-like sweep (bench/RESULTS.md, 6 such replans
  re-solved to convergence): window time +0.0 to +1.0 s of ~70 s, target power within
  18 W. The soft terminal W' target is not part of the check: one capped iterate was
  1.0 s faster than the optimum by ending its window 2.8 kJ below that target (W' still
  >= 0; the next replan, from the measured W', prices the deficit again).
  Capped iterates that are not yet feasible (open continuity gaps) are failures. A
  converged solution must pass the same check: on the slacks, IPOPT can converge to a
  window that asks 1.8x the grip where the measured start used 1.2 (a perturbed start
  above a hairpin of tests/ocp/test_horizon.py's descent, once attempts could run to
  150 iterations), which no rider can follow (`BEYOND_LIMITS`: the next attempt is
  tried).
- Rescue by continuation in the E9 switch, after both attempts failed (`horizon_rescue`).
  Why they fail: a rider who pedals near critical power rides right on the kink of E9
  (W' drains at the full rate above CP, recovers at `(1 - E_n)` of it below), which the
  model smooths over only `sharpness_w` = 5 W. Newton steps computed outside that band
  see almost no curvature in the power direction and jump across it: the solver's
  iterates 2-cycle (power +-100 W mid-window, the objective up and down by ~1 s) until
  the cap. Measured on the Zwift Bologna ride (CP 285 W, ridden at 270-300 W for half an
  hour; bench/RESULTS.md): 19 % of the advice were fallbacks; the same NLPs with the
  switch smoothed over 20 W converged, median 20 iterations (with this rescue and
  `max_window_s`: 0.5 % fallbacks, median 16 iterations per replan). The 20 W model alone
  is not the advice: its softplus drains W' by up to `0.69 x 20 W x E_n` too much near
  CP, which advised 10-20 W below the exact optimum. So the rescue solves the 20 W NLP
  (`rescue_sharpness_w`, same layout, from the attempts' starts), then polishes it in
  the exact NLP; if the polish is not usable, the 20 W solution is advised with W'
  recomputed by the exact E9 (status "Smoothed_Feasible", counted as unconverged): only
  E9 differs between the two models, so every other state obeys the exact dynamics as
  it is, and the exact W' is never below the smooth one - the iterate passes `feasible`
  (dynamics, road, grip, W' >= 0) like any other. It errs on the cautious side (W'
  spent later), and only where the exact NLP found nothing.
- Two RK4 substeps per interval in a stiff window (`stiff`), and every solution
  integrated again with four times as many (`HorizonNlp.resolved`) before it is
  advised: at a crawl up a steep ramp one step per 4-5 m interval was outside RK4's
  stable range, and IPOPT converged on the artefact (2.5 -> 27 m/s in 10 m up 22 %;
  `HorizonSettings.stiff_substeps`). A solution whose intervals do not hold is a
  failure ("Unresolved_Dynamics"), whatever IPOPT said.
- Windows of at most `max_window_s` of the plan's riding (never under `min_window_m`):
  a fixed node count over 1 km up a slow climb made intervals of ~4 s, stiff and failing
  (`HorizonSettings`); and of at most `max_density_ratio` times the nodes the mesh asks
  for: 1 km of switchbacks asked for three times the window's nodes.
- Hard caps: `max_iter` and `max_wall_time_s` (per replan, shared as above and with the
  rescue, `rescue_share`); a failure
  returns `success=False` with the solver's raw status per attempt and never raises.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.model.conditions import Conditions
from itt_planner.model.dynamics import build_3d_steady_lean, steady_lean_rad
from itt_planner.model.params import ModelParams
from itt_planner.model.rider import Rider
from itt_planner.model.state import RiderState
from itt_planner.ocp.horizon_nlp import HorizonNlp
from itt_planner.ocp.horizon_rescue import usable
from itt_planner.ocp.horizon_settings import (
    UNRESOLVED,
    HorizonSettings,
    HorizonSolution,
)
from itt_planner.ocp.horizon_window import HorizonWindow
from itt_planner.ocp.mesh import road_data, speed_spacing_m
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import PlanStatus, SolveResult

log = logging.getLogger(__name__)



class HorizonPlanner:
    """Receding-horizon OCP built once; `solve(state)` many times (never raises)."""

    def __init__(self, course: Course, rider: Rider, plan: Plan,
                 conditions: Conditions = Conditions(),
                 settings: HorizonSettings = HorizonSettings()) -> None:
        self.course, self.rider, self.plan = course, rider, plan
        self.conditions, self.settings = conditions, settings
        self._model = build_3d_steady_lean(eps_wn=settings.eps_wn,
                                           sharpness_w=settings.sharpness_w)
        self._par = ModelParams(rider, conditions, settings.w_delta, settings.w_power).vector()
        self._window = HorizonWindow(self._model, course, rider, plan, conditions, settings)
        # The stiff windows' NLP is built at the first such window: a node starts
        # 0.16 s sooner (0.10 s against 0.26 s), and most courses never need it.
        self._nlps = {settings.substeps: HorizonNlp(self._model, settings, settings.substeps,
                                                    self._par)}
        self._tr = self._nlps[settings.substeps].tr  # the layout and parameters of both
        self._previous: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._previous_mult: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._failures = 0

    @property
    def state_names(self) -> tuple[str, ...]:
        """Names of the rows of `initial_state` (the horizon model's states)."""
        return self._model.states

    def window(self, s_m: float) -> np.ndarray:
        """The fixed-count node positions of the window starting at `s_m`
        (`HorizonWindow.nodes`)."""
        return self._window.nodes(s_m)

    def initial_state(self, state: RiderState, s_m: float) -> np.ndarray:
        """State vector of the horizon model from the estimate (`HorizonWindow`)."""
        return self._window.initial_state(state, s_m)

    def corner_speed_cap(self, nodes: np.ndarray, v0: float, w_n0: float = -1.0
                         ) -> np.ndarray:
        """Upper speed bound per node from the plan's corners, for a rider at `v0` with
        the command `w_n0` (`HorizonWindow.corner_speed_cap`)."""
        return self._window.corner_speed_cap(nodes, v0, w_n0)

    # ---- warm start ----------------------------------------------------------------------
    def _guess(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray, str]:
        x, u = self._window.plan_guess(nodes)
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

    def _shift_multipliers(self, nodes: np.ndarray
                           ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The previous solution's multipliers moved onto `nodes` (zero beyond its end)."""
        if not self.settings.warm_multipliers or self._previous_mult is None:
            return None, None
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
        return lam_x_new, lam_g_new

    # ---- solve -------------------------------------------------------------------------------
    def solve(self, state: RiderState) -> HorizonSolution:
        """Replan from `state`. Never raises on solver failure: `success=False` + status."""
        t0 = time.perf_counter()
        st = self.settings
        s_est = float(state.s_m) if math.isfinite(state.s_m) else 0.0
        s0 = float(np.clip(s_est, 0.0, self.course.length_m - 1.0))
        nodes = self.window(s0)
        lay, m = self._tr.layout, self._model
        bounds = self._window.bounds(nodes, self.initial_state(state, s0))
        x0 = bounds.x0
        nlp = self._nlp(st.stiff_substeps if self.stiff(nodes, float(x0[m.index("v")]))
                        else st.substeps)
        end = nodes[-1]
        e_target = self._window.terminal_e_n(nodes, float(x0[m.index("e_n")]))
        terminal = np.array([e_target, float(self.plan.at("v_mps", end)), st.v_weight,
                             float(self.plan.at("costate_v_s_per_mps", end))])
        road = road_data(self.course, nodes)
        p = nlp.tr.params(road, self._par, terminal)
        lbw, ubw = bounds.decision(lay)
        if self._failures >= st.reset_after_failures:
            self.reset()  # the last good solution is too far behind to be a good start
        x_guess, u_guess, start = self._guess(nodes)
        kinds = ("warm", "retry") if start == "shifted" else ("cold",)
        statuses, iterations = [], 0
        starts = []  # the attempts' starts: the rescue's too
        for kind in kinds:
            if kind == "retry":  # the plan re-anchored at the rider: a start from elsewhere
                x_guess, u_guess = self._window.plan_guess(nodes)
            if kind != "warm":  # the plan re-anchored at the rider (`HorizonWindow.anchor`)
                x_guess = self._window.anchor(nodes, x_guess, x0, lay.split(lbw)[0],
                                              lay.split(ubw)[0])
            x_guess[:, 0] = x0
            lam_x0, lam_g0 = self._shift_multipliers(nodes) if kind == "warm" else (None, None)
            starts.append(lay.join(x_guess, u_guess))
            res = nlp.solvers[kind].solve(starts[-1], p, lbw, ubw,
                                          lam_x0=lam_x0, lam_g0=lam_g0)
            if res.raw_status.startswith("error: "):
                log.warning("horizon solve (%s) raised: %s", kind, res.raw_status)
            iterations += res.iterations
            statuses.append(res.raw_status)
            outcome = res.status
            success, verdict = usable(nlp.feasible, res, p, lbw, ubw)
            statuses.extend(verdict)
            if success:
                break
        if not success and nlp.rescue is not None:
            rescued, status, its = nlp.rescue.solve(starts, p, lbw, ubw)
            iterations += its
            statuses.append(status)
            if rescued is not None:
                res, success, outcome = rescued, True, rescued.status
        if success and not nlp.resolved(res.w, road):
            success = False
            statuses.append(UNRESOLVED)
        return self._solution(state, nodes, (nlp, p), res, success, outcome, statuses,
                              iterations, t0)

    def _solution(self, state: RiderState, nodes: np.ndarray, nlp_p: tuple[HorizonNlp, np.ndarray],
                  res: SolveResult, success: bool, outcome: PlanStatus, statuses: list[str],
                  iterations: int, t0: float) -> HorizonSolution:
        """The last attempt's profiles; a usable one is kept as the next warm start."""
        nlp, p = nlp_p
        lay, m, w = nlp.tr.layout, self._model, res.w
        x, u, _ = lay.split(w)
        dt, y = (np.asarray(a) for a in nlp.tr.evaluate(w, p))
        t = np.concatenate([[0.0], np.cumsum(dt.ravel())])
        status = statuses[-1] if success else "; ".join(statuses)
        if success:
            self._failures = 0
            self._previous = (nodes, x, u)
            self._previous_mult = ((nodes, res.lam_x, res.lam_g)
                                   if res.lam_x is not None and res.lam_g is not None else None)
        else:
            self._failures += 1
            log.warning("horizon solve at s=%.0f m: %s after %d iterations", nodes[0], status,
                        iterations)
        end = nodes[-1]
        e_j = x[m.index("e_n")] * self.rider.w_prime_j
        plan_rest_t = self.plan.finish_time_s - float(self.plan.at("t_s", end))
        plan_rest_w = float(self.plan.w_prime_j[-1] - self.plan.at("w_prime_j", end))
        return HorizonSolution(
            s_m=nodes, n_m=x[m.index("n")], v_mps=x[m.index("v")], power_w=y[0],
            phi_rad=np.asarray(steady_lean_rad(y[2])), t_s=t, w_prime_j=e_j, success=success,
            status=status, outcome=outcome, iterations=iterations,
            solve_time_s=time.perf_counter() - t0,
            predicted_finish_s=state.elapsed_s + float(t[-1]) + plan_rest_t,
            w_prime_finish_j=float(e_j[-1]) + plan_rest_w)

    def _nlp(self, substeps: int) -> HorizonNlp:
        if substeps not in self._nlps:
            self._nlps[substeps] = HorizonNlp(self._model, self.settings, substeps, self._par)
        return self._nlps[substeps]

    def stiff(self, nodes: np.ndarray, v0_mps: float) -> bool:
        """Whether one RK4 step per interval of the window `nodes` is outside its stable
        range somewhere: `h 2 a / v^2` over `stiff_ratio` (`mesh.speed_spacing_m`), with
        `v` the plan's speed or the rider's where slower, `a` the plan's pedalling force
        per unit mass at that speed."""
        v = np.maximum(np.minimum(self.plan.at("v_mps", nodes[:-1]), v0_mps), 1.0)
        accel = np.abs(self.plan.at("power_w", nodes[:-1])) / (self.rider.mass_kg * v)
        return bool(np.max(np.diff(nodes) / speed_spacing_m(v, accel)) > self.settings.stiff_ratio)

    def reset(self) -> None:
        """Forget the warm start (e.g. after a jump of the estimate)."""
        self._previous = None
        self._previous_mult = None
        self._failures = 0

