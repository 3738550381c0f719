"""Where a receding-horizon replan starts: the window's nodes, the rider's estimate as the
model's initial state, the plan as a guess, and the simple bounds over the window.

Everything here is numeric and fixed by the course, the rider, the plan and the settings
(`HorizonWindow`); the solver, the warm start and the feasibility check are
`horizon.HorizonPlanner`'s. Why the window and the bounds look as they do: `horizon`.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import cumulative_trapezoid

from itt_planner.course.geometry import Course
from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.dynamics import SpatialModel
from itt_planner.model.rider import Rider
from itt_planner.model.state import RiderState
from itt_planner.model.wprime import e_n_along
from itt_planner.ocp.bounds import U_W_MAX, V_MIN_MPS, Bounds, simple_bounds, speed_limit_mps
from itt_planner.ocp.guess import PLAN_ARRAYS, plan_spacing_cap
from itt_planner.ocp.horizon_settings import HorizonSettings
from itt_planner.ocp.mesh import target_spacing
from itt_planner.ocp.plan import Plan

#: Distance over which a cold start joins the plan's line and speed from the rider's (m):
#: 5 m across the road at a heading of 0.05 rad.
_REJOIN_M = 100.0


class HorizonWindow:
    """The numeric set-up of replans on one course for one rider and one plan."""

    def __init__(self, model: SpatialModel, course: Course, rider: Rider, plan: Plan,
                 conditions: Conditions, settings: HorizonSettings) -> None:
        self.model, self.course, self.rider, self.plan = model, course, rider, plan
        self.conditions, self.settings = conditions, settings
        # Finer where the plan is slow (the launch): `dv/ds = a/v` is stiff there (issue 18).
        self._spacing = target_spacing(course, settings.h_min_m, settings.h_max_m,
                                       h_cap_m=plan_spacing_cap(course, plan, rider, conditions))

    def nodes(self, s_m: float) -> np.ndarray:
        """The fixed-count node positions of the window starting at `s_m`.

        Equal steps of the cumulative node density `1/h`, with `h` the course's mesh
        spacing capped by `h_min_m + near_grade * (distance ahead)`. A window cut short
        by the finish (or by `max_window_s`) may have more nodes than that density asks for:
        the surplus is spread evenly (an added uniform density) instead of shrinking
        every interval alike, which left 0.85 m first intervals in a 150 m window, too
        short to steer from a measured line (a grip violation of 3x at the first node
        in test_horizon).
        """
        st, c, plan = self.settings, self.course, self.plan
        end = min(s_m + st.horizon_m, c.length_m)
        if st.max_window_s > 0:  # no more than `max_window_s` of the plan's riding
            t_end = float(plan.at("t_s", s_m)) + st.max_window_s
            end = min(end, max(float(np.interp(t_end, plan.t_s, plan.s_m)),
                               s_m + st.min_window_m))
        s_m = min(s_m, end - 1.0)
        grid, cum = self._asked(s_m, end)
        asked = st.max_density_ratio * st.n_intervals
        if 0 < asked < cum[-1]:  # no more bends than the nodes can follow
            end = max(float(np.interp(asked, cum, grid)), min(s_m + st.min_window_m, end))
            grid, cum = self._asked(s_m, end)
        if end - s_m < st.horizon_m - 1.0:  # the surplus as an added uniform density
            cum = cum + max(st.n_intervals - float(cum[-1]), 0.0) * (grid - s_m) / (end - s_m)
        nodes: np.ndarray = np.interp(np.linspace(0.0, cum[-1], st.n_intervals + 1), cum, grid)
        nodes[0], nodes[-1] = s_m, end
        return nodes

    def _asked(self, s_m: float, end_m: float) -> tuple[np.ndarray, np.ndarray]:
        """The course grid over [`s_m`, `end_m`] and the number of intervals the mesh asks
        for from `s_m` to each point: the integral of the node density `1/h`, with the
        course's spacing `h` finer near the rider (`near_grade`)."""
        st, c = self.settings, self.course
        grid = np.concatenate([[s_m], c.s_m[(c.s_m > s_m) & (c.s_m < end_m)], [end_m]])
        h = np.minimum(np.interp(grid, c.s_m, self._spacing),
                       st.h_min_m + st.near_grade * (grid - s_m))
        return grid, cumulative_trapezoid(1.0 / h, grid, initial=0)

    def initial_state(self, state: RiderState, s_m: float) -> np.ndarray:
        """State vector of the horizon model from the estimate (steering: from the plan)."""
        r, m = self.rider, self.model
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
        if self.plan.model != "1d":  # 3D, or the line's steady turn (`line_plan.onto_road`)
            return self.plan.at("delta_n", nodes)
        # A plain 1D plan: the steering of the steady turn along the centre line.
        kappa = self.course.at("kappa_per_m", nodes)
        return np.arctan(self.rider.wheelbase_m * kappa) / self.rider.steer_max_rad

    def plan_guess(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The plan on `nodes` as the horizon model's states and controls."""
        m, plan = self.model, self.plan
        x = np.zeros((m.nx, len(nodes)))
        for name in ("n", "alpha", "v", "w_n", "e_n"):
            x[m.index(name)] = plan.at(PLAN_ARRAYS[name], nodes)
        x[m.index("delta_n")] = self._plan_delta_n(nodes)
        u = np.vstack([plan.at(PLAN_ARRAYS[name], nodes[:-1]) for name in ("u_delta", "u_w")])
        return x, u

    def anchor(self, nodes: np.ndarray, x: np.ndarray, x0: np.ndarray, x_lo: np.ndarray,
               x_hi: np.ndarray) -> np.ndarray:
        """A start from the plan (`plan_guess`, states `x`) re-anchored at the rider's `x0`.

        W' from the rider's, riding the plan's power (`_ridden_e_n`: what the terminal
        target asks for, `terminal_e_n`); the line and the speed by the rider's offsets,
        fading out over `_REJOIN_M`, within the bounds `x_lo`, `x_hi`. Why: with only
        the first node moved, a rider ridden 5.4 m across the road from the plan's line
        (a recorded ride of an older plan's line) started IPOPT from a 5.4 m jump in a
        3 m interval, and the cold replans hit the iteration cap (verona-like replay,
        14.4 km). With the plan's W' shifted, a rider with W' to spare over a plan that
        had emptied it started above full W' (Sauerland, bench/RESULTS.md, 2026-12-03).
        """
        m, x = self.model, x.copy()
        ie = m.index("e_n")
        x[ie] = self._ridden_e_n(nodes, float(x0[ie]))
        fade = np.clip(1.0 - (nodes - nodes[0]) / _REJOIN_M, 0.0, 1.0)
        for i in (m.index("n"), m.index("v")):
            x[i] = np.clip(x[i] + fade * (x0[i] - x[i, 0]), x_lo[i], x_hi[i])
        x[:, 0] = x0
        return x

    def terminal_e_n(self, nodes: np.ndarray, e0: float) -> float:
        """The W' (as E_n) the window should end with: its soft terminal target.

        The rider's deviation from the plan's W' is carried to the window's end through
        E9 along the plan's power and time (`_ridden_e_n` from the rider's W', against
        the same from the plan's), and the share of the remaining course beyond the
        window is kept (`horizon` module docstring, "Terminal treatment"). Why through
        E9 rather than added as it is: recovery below CP slows as W' fills (Skiba), so a
        rider with W' left over a plan that emptied it recovers less over a descent than
        the plan does. Added as it is, the target was unreachable: on the Sauerland ride
        (km 9, the rider 59 % full where a re-solved plan had emptied W' on the climb) it
        was 1.06, above full, and 35 of the ride's first 45 failed replans were such
        windows (bench/RESULTS.md, 2026-12-03). Carried through E9, riding the plan's
        power reaches it.
        """
        s0, end = float(nodes[0]), float(nodes[-1])
        ends = np.array([s0, end])
        deviation = (self._ridden_e_n(ends, e0)[-1]
                     - self._ridden_e_n(ends, float(self.plan.at("e_n", s0)))[-1])
        beyond = (self.course.length_m - end) / max(self.course.length_m - s0, 1.0)
        return float(np.clip(float(self.plan.at("e_n", end)) + deviation * beyond, 0.0, 1.0))

    def _ridden_e_n(self, s_m: np.ndarray, e0: float) -> np.ndarray:
        """E_n at the increasing `s_m` for a rider with `e0` at `s_m[0]` who rides the
        plan's power at the plan's pace (E9, Euler steps on the plan's own intervals:
        ~1 s, over which W' changes by < 1 %)."""
        plan, r = self.plan, self.rider
        inside = plan.s_m[(plan.s_m > s_m[0]) & (plan.s_m < s_m[-1])]
        grid = np.unique(np.concatenate([s_m, inside]))
        dt = np.diff(plan.at("t_s", grid))
        p_plus = np.maximum(plan.at("power_w", 0.5 * (grid[1:] + grid[:-1])), 0.0)
        e = e_n_along(e0, p_plus.tolist(), dt.tolist(), r.critical_power_w, r.w_prime_j,
                      floor=0.0)
        return np.asarray(np.interp(s_m, grid, e))

    def bounds(self, nodes: np.ndarray, x0: np.ndarray) -> Bounds:
        """The simple bounds (`bounds.simple_bounds`) over the window, the speed capped by
        physics over the window and by the plan's corner speeds (`corner_speed_cap`)."""
        v0 = float(x0[self.model.index("v")])
        w_n0 = float(x0[self.model.index("w_n")])
        v_max = np.minimum(self.corner_speed_cap(nodes, v0, w_n0),
                           speed_limit_mps(self.course, nodes, self.rider, self.conditions, v0))
        return simple_bounds(self.model, self.course, nodes, x0,
                             margin_m=self.settings.margin_m, v_max_mps=v_max)

    def corner_speed_cap(self, nodes: np.ndarray, v0: float, w_n0: float = -1.0
                         ) -> np.ndarray:
        """Upper speed bound per node: the plan's speed where the plan corners at the grip
        limit (friction use >= `corner_cap_use`), plus `corner_cap_tol_mps`.

        Why: there the speed is set by grip and by leaning in and out, and the plan,
        solved with the roll dynamics E4-E5, knows what that costs; the steady-lean
        horizon model does not (it tips into a lean at once), so on its own it planned
        braking later and entering tight corners 0.5-1 m/s faster than any rider can
        lean in, and a rider following that ran wide (bench/RESULTS.md). Elsewhere the
        speed stays free (pacing). The cap never asks for more than braking at
        `corner_cap_brake_g` g from the rider's speed gives (a rider measured too fast
        still has a feasible NLP). That braking starts once the command `w_n` has ramped
        from the rider's `w_n0` to it at the fastest rate E6 allows (no deceleration is
        credited before): a rider measured coasting 1.1 m/s over the plan at a corner
        entry could not lose 0.3 g worth of speed in the first 4.8 m interval (`w_n`
        from 0 reaches -0.3 only after ~0.22 s) and the NLP was infeasible (verona-like
        replay, 3 of its 10 fallbacks). The default `w_n0` = -1 (braking fully) credits
        braking from the first metre.
        """
        st, plan, r = self.settings, self.plan, self.rider
        cap = np.where(plan.at("friction_use", nodes) >= st.corner_cap_use,
                       plan.at("v_mps", nodes) + st.corner_cap_tol_mps, np.inf)
        w_brake = -st.corner_cap_brake_g / self.conditions.mu_x
        rate_per_s = U_W_MAX * r.power_rate_max_wps / r.max_power_w  # E6
        lag_m = v0 * max(w_n0 - w_brake, 0.0) / rate_per_s
        reach = np.sqrt(np.maximum(v0 ** 2 - 2 * st.corner_cap_brake_g * GRAVITY_MPS2
                                   * np.maximum(nodes - nodes[0] - lag_m, 0.0), 0.0))
        bound: np.ndarray = np.maximum(cap, np.maximum(reach, V_MIN_MPS))
        return bound
