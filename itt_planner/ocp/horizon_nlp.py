"""The receding-horizon NLP for one count of RK4 substeps: its transcription, solvers
and rescue, and the two checks a solution passes before it is advice (`feasible`,
`resolved`).

`HorizonPlanner` keeps one for `HorizonSettings.substeps` and one for `stiff_substeps`
(a window where one RK4 step per interval is outside its stable range: a crawl up a
steep ramp). Both have the same decision vector and parameters, so a warm start moves
from one to the other as it is.
"""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np

from itt_planner.model.dynamics import SpatialModel, rk4_step
from itt_planner.ocp.horizon_rescue import HorizonRescue, rescue_enabled
from itt_planner.ocp.horizon_settings import HorizonSettings
from itt_planner.ocp.solver import horizon_solver
from itt_planner.ocp.transcription import transcribe

#: W' (as E_n) a usable iterate may undershoot 0 by: the solver's bound relaxation only.
_W_PRIME_TOL = 1e-6


class HorizonNlp:
    """One transcription of the horizon OCP and its solvers (`horizon` module docstring).

    Args:
        model: the steady-lean 3D model.
        settings: the horizon's settings; `substeps` is replaced by the one given.
        substeps: RK4 steps per interval of this NLP.
        par: the model's parameter vector (`ModelParams.vector`), for the rescue and
            `resolved`.
    """

    def __init__(self, model: SpatialModel, settings: HorizonSettings, substeps: int,
                 par: np.ndarray) -> None:
        st = self.settings = dataclasses.replace(settings, substeps=substeps)
        self.model, self.par = model, par
        # Without the transcription's acceleration bound (issue 18): the window never
        # starts below 1 m/s (`initial_state`), its spacing follows the plan's speed and
        # its speed is bounded by physics (`bounds.speed_limit_mps`); with the bound the
        # technical-descent sweep of test_horizon lost a usable replan (47 vs 48 of 50)
        # and one converged window broke grip at its first node.
        self.tr = transcribe(model, st.n_intervals, substeps=substeps, soft=True,
                             slack_weight=st.slack_weight, accel_bound=False)
        # Three solvers over the same NLP and derivative Functions (building is cheap):
        # the budget is a solver option, so the warm attempt and the cold retry after
        # it get their shares of the wall time, a cold first start all of it (less the
        # rescue's share).
        rescue = rescue_enabled(st)
        budget = st.max_wall_time_s * (1.0 - (st.rescue_share if rescue else 0.0))
        self.solvers = {
            kind: horizon_solver(self.tr, f"horizon_{kind}_{substeps}", warm=kind == "warm",
                                 max_iter=st.max_iter, max_wall_time_s=wall,
                                 tol=st.tol, acceptable_iter=st.acceptable_iter)
            for kind, wall in (("warm", st.warm_share * budget), ("cold", budget),
                               ("retry", (1.0 - st.warm_share) * budget))}
        nlp = self.tr.nlp
        self._g = ca.Function("horizon_g", [nlp["x"], nlp["p"]], [nlp["g"]])
        self._fine = rk4_step(model, 4 * substeps).map(st.n_intervals)
        self.rescue = (HorizonRescue(model, self.tr, st, par, self.feasible)
                       if rescue else None)

    def feasible(self, w: np.ndarray, p: np.ndarray, lbw: np.ndarray, ubw: np.ndarray) -> bool:
        """Whether an iterate is valid advice: dynamics, road, grip and W' respected.

        The continuity gaps (E1-E9 integrated over each interval) and the simple bounds
        (road edges C11, W' >= 0 C12, actuators C13-C14) within `feasible_tol`, W' not
        below 0 beyond the solver's bound relaxation, and the path constraints themselves
        (grip C16, pedalling C15; their slacks only make the NLP solvable) within
        `grip_tol` of their limit or of what the measured initial state already uses.
        The soft terminal W' target is not checked: it is a price, not a safety limit.
        """
        st, lay = self.settings, self.tr.layout
        if np.any(w < lbw - st.feasible_tol) or np.any(w > ubw + st.feasible_tol):
            return False
        x, _, slacks = lay.split(w)
        if np.any(x[self.model.index("e_n")] < -_W_PRIME_TOL):
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

    def resolved(self, w: np.ndarray, road: np.ndarray) -> bool:
        """Whether each interval (`road`: its road data, ROAD x intervals), integrated
        again with four times the substeps, ends within `resolve_tol_mps` + 5 % of its
        next node's speed: the solution does not ride the RK4 map beyond where it holds
        (`HorizonSettings.substeps`)."""
        x, u, _ = self.tr.layout.split(w)
        x_end = np.asarray(self._fine(x[:, :-1], u, road, self.par)[0])
        iv = self.model.index("v")
        v_next = x[iv, 1:]
        return bool(np.all(np.abs(x_end[iv] - v_next)
                           <= self.settings.resolve_tol_mps + 0.05 * np.abs(v_next)))
