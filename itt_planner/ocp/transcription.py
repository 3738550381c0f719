"""Direct multiple shooting of a spatial OCP into an NLP with explicit stage structure.

Why multiple shooting: the roll dynamics (E4-E5) are an unstable inverted pendulum with
a time constant of ~0.45 s. Single shooting would integrate that instability over the
whole course; collocation needs several collocation points per metre. Multiple shooting
with RK4 restarts the integration at every node, so each interval sees at most one step
of the instability (prototype: RK4 per 1-2 m converged in 2.5x fewer iterations than RK2).

Layout: the decision vector is ordered stage by stage, `[x_0, u_0, s_0, x_1, u_1, s_1,
..., x_N (, e)]` (`s_k`: slacks of the softened path constraints, `e`: the terminal W'
slack; both only when `soft`). The constraints are the continuity gaps (interval-major),
then the path constraints C15/C16 (node-major; node k's with interval k's road data, the
last node's with the last interval's, but the curvature over the node's two intervals,
`verify.node_curvature`: with interval k's a node at an arc's end had the straight's),
then the acceleration bounds (one per interval, below), then the soft terminal condition.

Acceleration bound (issue 18, sound transcription at every speed): in the spatial domain
`dv/ds = a / v`, so one RK4 step of 10 m from 0.5 m/s turned 560 W into 580 m/s, and
IPOPT found a "rest and sprint" optimum that rode on that artefact. Whatever the
integrator does, a physical ride cannot gain speed faster than the tyres (C16, `mu_x g`)
plus gravity (and a tail wind's push) allow, so every interval carries `(v_{k+1}^2 -
v_k^2) / (2 ds) <= mu_x g - g sin(beta) + k_v V_w^2 / m` (rolling resistance and drag
only make the true bound tighter; never active at a physical optimum). It couples the
speeds of two neighbouring nodes only: its Jacobian has two entries per row and its
Hessian is diagonal (folded into the stage kernels' `v^2` term).
Everything that changes between solves is a bound (initial state, road widths, W' >= 0)
or an NLP parameter (road data, model parameters, terminal data: not in the sparsity
patterns), so one NLP serves any section with the same node count.

Derivatives: the Lagrangian's Hessian is block diagonal (one block per stage: interval
cost, integrator and path constraints of that stage) and the constraint Jacobian is
block banded. Instead of letting CasADi differentiate an N-times-mapped graph (the
prototype spent 90 % of its time there), six small per-stage kernels - the integrator,
its Jacobian, the stage Hessian, the path constraints, the final-node Hessian and the
cost gradient (called twice per iteration: with the integrator's Jacobian it cost as
much as the constraint Jacobian) - are derived once, compiled to C once per machine
(`codegen.compiled`), mapped over the stages, and their dense blocks scattered into the
known sparsity patterns. IPOPT gets them through its `grad_f`, `jac_g` and `hess_lag`.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np

from itt_planner.model.conditions import GRAVITY_MPS2
from itt_planner.model.dynamics import SpatialModel, rk4_step
from itt_planner.model.params import PARAMS, ROAD
from itt_planner.ocp.codegen import compiled

#: Terminal data of the soft terminal treatment: [E_n target, v target, v weight
#: (s/(m/s)^2), v price (s/(m/s): the change of the time to go per m/s carried over the
#: end, negative when speed saves time)].
TERMINAL = ("e_n_target", "v_target", "v_weight", "v_price")
#: Penalty of the terminal W' slack relative to the path-constraint slacks.
_TERMINAL_SLACK_FACTOR = 10.0


@dataclass(frozen=True)
class Layout:
    """Index bookkeeping of the decision vector."""

    nx: int
    nu: int
    ns: int  # slacks per stage (0 for hard constraints)
    n_intervals: int
    n_path: int
    accel: bool = True  # the acceleration bounds are rows of g

    @property
    def n_gap(self) -> int:
        """Number of continuity constraints (first in g)."""
        return self.nx * self.n_intervals

    @property
    def accel_rows(self) -> slice:
        """Where the acceleration bounds sit in g (after the path constraints)."""
        start = self.n_gap + self.n_path * self.n_nodes
        return slice(start, start + (self.n_intervals if self.accel else 0))

    @property
    def n_g(self) -> int:
        """Number of constraints: gaps, path, acceleration bounds, soft terminal."""
        return (self.n_gap + self.n_path * self.n_nodes
                + (self.n_intervals if self.accel else 0) + (1 if self.ns else 0))

    def g_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lbg, ubg): the continuity gaps are equalities, every other row is <= 0."""
        return (np.concatenate([np.zeros(self.n_gap), np.full(self.n_g - self.n_gap, -np.inf)]),
                np.zeros(self.n_g))

    @property
    def stage(self) -> int:
        return self.nx + self.nu + self.ns

    @property
    def n_var(self) -> int:
        return self.stage * self.n_intervals + self.nx + (1 if self.ns else 0)

    @property
    def n_nodes(self) -> int:
        return self.n_intervals + 1

    def x_index(self, k: int | np.ndarray, i: int | np.ndarray) -> np.ndarray:
        """Position of state i of node k in the decision vector."""
        return np.asarray(np.asarray(k) * self.stage + np.asarray(i))

    def split(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Numeric decision vector -> X (nx x N+1), U (nu x N), S (ns x N)."""
        w = np.asarray(w, dtype=float).ravel()
        n = self.n_intervals
        body = w[: self.stage * n].reshape(n, self.stage).T
        x = np.hstack([body[: self.nx], w[self.stage * n: self.stage * n + self.nx, None]])
        return x, body[self.nx: self.nx + self.nu], body[self.nx + self.nu:]

    def join(self, x: np.ndarray, u: np.ndarray, s: np.ndarray | None = None,
             terminal_slack: float = 0.0) -> np.ndarray:
        """Inverse of `split` (slacks default to zero)."""
        n = self.n_intervals
        s = np.zeros((self.ns, n)) if s is None else s
        body = np.vstack([x[:, :n], u[:, :n], s]).T.ravel()
        tail = [x[:, n]] + ([np.array([terminal_slack])] if self.ns else [])
        return np.concatenate([body, *tail])


@dataclass(frozen=True)
class Transcription:
    """The NLP of one model over N intervals, its derivative Functions and its layout."""

    model: SpatialModel
    layout: Layout
    nlp: dict[str, ca.MX]
    derivatives: dict[str, ca.Function]
    lbg: np.ndarray
    ubg: np.ndarray
    #: Function (w, p) -> (dt per interval, outputs per node) for post-processing.
    evaluate: ca.Function

    def params(self, road: np.ndarray, par: np.ndarray,
               terminal: np.ndarray | None = None) -> np.ndarray:
        """The NLP parameter vector: road data (column-major), model params, terminal."""
        parts = [np.asarray(road, float).T.ravel(), np.asarray(par, float)]
        if self.layout.ns:
            parts.append(np.zeros(len(TERMINAL)) if terminal is None else terminal)
        return np.concatenate(parts)


#: Keyed by the model's expressions, not its name (a model rebuilt with other constants).
_KERNELS: dict[tuple[str, int, bool], tuple[ca.Function, ...]] = {}


def stage_kernels(model: SpatialModel, substeps: int, compile_c: bool = True
                  ) -> tuple[ca.Function, ...]:
    """The six per-stage kernels (see module docstring), compiled and cached."""
    content = (model.ode.serialize() + model.path.serialize()).encode()
    key = (hashlib.sha256(content).hexdigest(), substeps, compile_c)
    if key not in _KERNELS:
        _KERNELS[key] = _build_kernels(model, substeps, compile_c)
    return _KERNELS[key]


def _build_kernels(model: SpatialModel, substeps: int, compile_c: bool
                   ) -> tuple[ca.Function, ...]:
    nx, nu = model.nx, model.nu
    x, u = ca.SX.sym("x", nx), ca.SX.sym("u", nu)
    # road: the interval's (integrator); road_n: the node's (path constraints; docstring).
    road, road_n = ca.SX.sym("road", len(ROAD)), ca.SX.sym("road_n", len(ROAD))
    p, n_path = ca.SX.sym("p", len(PARAMS)), int(model.path.size1_out(0))
    sigma, lam, mu = ca.SX.sym("sigma"), ca.SX.sym("lam", nx), ca.SX.sym("mu", n_path)
    v_target, v_weight = ca.SX.sym("v_target"), ca.SX.sym("v_weight")
    nu_v = ca.SX.sym("nu_v")  # the node's share of the acceleration bounds' Hessian (v^2)
    tag = f"{model.ode.name()}_{substeps}_acc"
    xf, dt, dj = rk4_step(model, substeps)(x, u, road, p)
    z = ca.vertcat(x, u)
    g = model.path(x, road_n, p)  # the road is a parameter, not a variable
    v_sq = x[model.index("v")] ** 2
    lag = sigma * dj + ca.dot(lam, xf) + ca.dot(mu, g) + nu_v * v_sq
    lag_n = (ca.dot(mu, g) + sigma * v_weight * (x[model.index("v")] - v_target) ** 2
             + nu_v * v_sq)
    kernels = [
        ca.Function(f"itt_F_{tag}", [x, u, road, p], [xf, dt, dj]),
        ca.Function(f"itt_JF_{tag}", [x, u, road, p], [ca.densify(ca.jacobian(xf, z))]),
        ca.Function(f"itt_HK_{tag}", [x, u, road, road_n, p, sigma, lam, mu, nu_v],
                    [ca.densify(ca.hessian(lag, z)[0])]),
        ca.Function(f"itt_P_{tag}", [x, road_n, p], [g, ca.densify(ca.jacobian(g, x))]),
        ca.Function(f"itt_HN_{tag}", [x, road_n, p, sigma, mu, v_target, v_weight, nu_v],
                    [ca.densify(ca.hessian(lag_n, x)[0])]),
        ca.Function(f"itt_GF_{tag}", [x, u, road, p], [ca.densify(ca.gradient(dj, z))]),
    ]
    if compile_c:
        return tuple(compiled(f"itt_kernels_{tag}", kernels))
    return tuple(kernels)


def _csc(n_rows: int, n_cols: int, rows: np.ndarray, cols: np.ndarray, src: np.ndarray
         ) -> tuple[ca.Sparsity, list[int]]:
    """Sparsity from triplets (no duplicates) and the source index of each nonzero."""
    order = np.lexsort((rows, cols))
    rows, cols, src = rows[order], cols[order], src[order]
    colind = np.concatenate([[0], np.cumsum(np.bincount(cols, minlength=n_cols))])
    return ca.Sparsity(n_rows, n_cols, colind.tolist(), rows.tolist()), src.tolist()


def _acceleration_bound(v_row: ca.MX, road: ca.MX, par: ca.MX, n: int
                        ) -> tuple[ca.MX, ca.MX, ca.MX, ca.MX]:
    """The acceleration bounds (module docstring): tyres + gravity + a tail wind's push.
    Returns (g rows, v_{k+1}, v_k, ds_k)."""
    q = {name: par[i] for i, name in enumerate(PARAMS)}
    ds_k, beta_k = road[3, :], road[1, :]
    wind_sq = q["wind_e"] ** 2 + q["wind_n"] ** 2
    a_up = (q["mu_x"] * GRAVITY_MPS2 - GRAVITY_MPS2 * ca.sin(beta_k)
            + q["k_v"] * wind_sq / q["mass"])
    v_to, v_from = v_row[0, 1:], v_row[0, :n]
    return ca.vec((v_to ** 2 - v_from ** 2) / (2 * ds_k) - a_up), v_to, v_from, ds_k


def _triplets(trip: Sequence[tuple[np.ndarray, ...]]
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rows, cols, src = (np.concatenate([np.ravel(t[i]) for t in trip]) for i in range(3))
    return rows, cols, src


def _jacobian_pattern(lay: Layout, iv: int, ie: int, ng: int
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(row, column, source value) of every nonzero of the constraint Jacobian; the
    values are `transcribe`'s: the stage blocks dF/dz, dpath/dx, then -1, then the
    acceleration rows' d/dv_{k+1} and d/dv_k."""
    nx, nz, n, n_path, st = lay.nx, lay.nx + lay.nu, lay.n_intervals, lay.n_path, lay.stage
    ng_gap, ng_path = nx * n, n_path * (n + 1)
    off_p, minus_one = nx * nz * n, nx * nz * n + n_path * nx * (n + 1)
    off_acc = minus_one + 1
    k, kn = np.arange(n), np.arange(n + 1)
    kk: np.ndarray  # index grids of the triplets below (their shapes vary)
    rr: np.ndarray
    cc: np.ndarray
    kk, rr, cc = np.meshgrid(k, np.arange(nx), np.arange(nz), indexing="ij")
    trip = [(kk * nx + rr, kk * st + cc, kk * nx * nz + cc * nx + rr)]  # dF/dz
    kk, rr = np.meshgrid(k, np.arange(nx), indexing="ij")
    trip.append((kk * nx + rr, lay.x_index(kk + 1, rr), np.full(kk.shape, minus_one)))  # -I
    kk, rr, cc = np.meshgrid(kn, np.arange(n_path), np.arange(nx), indexing="ij")
    trip.append((ng_gap + kk * n_path + rr, lay.x_index(kk, cc),
                 off_p + kk * n_path * nx + cc * n_path + rr))  # dpath/dx
    if lay.accel:
        row_acc = ng_gap + ng_path + k
        trip.append((row_acc, lay.x_index(k + 1, iv), off_acc + k))  # d/dv_{k+1}
        trip.append((row_acc, lay.x_index(k, iv), off_acc + n + k))  # d/dv_k
    if lay.ns:
        kk, rr = np.meshgrid(kn, np.arange(n_path), indexing="ij")
        trip.append((ng_gap + kk * n_path + rr, np.minimum(kk, n - 1) * st + nz + rr,
                     np.full(kk.shape, minus_one)))  # -slack
        trip.append((np.array([ng - 1, ng - 1]), np.array([lay.x_index(n, ie), lay.n_var - 1]),
                     np.array([minus_one, minus_one])))
    return _triplets(trip)


def _hessian_pattern(lay: Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(row, column, source value) of the upper triangle of the Lagrangian's Hessian; the
    values are `transcribe`'s: the stage blocks, the final node's block, then (soft) the
    slacks' and the terminal slack's diagonals."""
    nx, nz, n, st, ns = lay.nx, lay.nx + lay.nu, lay.n_intervals, lay.stage, lay.ns
    k = np.arange(n)
    off_n = nz * nz * n
    r_up, c_up = np.triu_indices(nz)
    kk = np.repeat(k, len(r_up))
    trip = [(kk * st + np.tile(r_up, n), kk * st + np.tile(c_up, n),
             kk * nz * nz + np.tile(c_up * nz + r_up, n))]
    r_up, c_up = np.triu_indices(nx)
    trip.append((lay.x_index(n, r_up), lay.x_index(n, c_up), off_n + c_up * nx + r_up))
    if ns:
        off_s = off_n + nx * nx
        diag = (k[:, None] * st + nz + np.arange(ns)[None, :]).ravel()
        trip.append((diag, diag, np.full(diag.shape, off_s)))
        trip.append((np.array([lay.n_var - 1]),) * 2 + (np.array([off_s + 1]),))
    return _triplets(trip)


def _hessian(lay: Layout, kernels: tuple[ca.Function, ca.Function],
             states: tuple[ca.MX, ca.MX, ca.MX], roads: tuple[ca.MX, ca.MX], par: ca.MX,
             term: ca.MX, lam_f: ca.MX, lam_g: ca.MX, ds_k: ca.MX, slack_weight: float
             ) -> ca.MX:
    """The upper triangle of the Lagrangian's Hessian (sparse MX): the stage kernels'
    dense blocks (`hk_k`, `hn_k`) scattered into `_hessian_pattern`. `states`: the node
    states, the controls and the last node's states; `roads`: the intervals', the nodes'."""
    (hk_k, hn_k), (road, node_road), (xs, us, x_last) = kernels, roads, states
    nx, n, n_path = lay.nx, lay.n_intervals, lay.n_path
    ng_gap, ng_path = nx * n, n_path * (n + 1)
    lam_gap = ca.reshape(lam_g[:ng_gap], nx, n)
    mu = ca.reshape(lam_g[ng_gap: ng_gap + ng_path], n_path, n + 1)
    # d^2/dv^2 of sum_k nu_k (v_{k+1}^2 - v_k^2) / (2 ds_k): node k gets
    # (nu_{k-1}/ds_{k-1} - nu_k/ds_k) / 2 as the coefficient of v_k^2.
    if lay.accel:
        nu_ds = ca.transpose(lam_g[ng_gap + ng_path: ng_gap + ng_path + n]) / (2 * ds_k)
        nu_node = ca.horzcat(0, nu_ds) - ca.horzcat(nu_ds, 0)
    else:
        nu_node = ca.MX.zeros(1, n + 1)
    h_stage = hk_k.map(n)(xs[:, :n], us, road, node_road[:, :n], par, lam_f, lam_gap,
                          mu[:, :n], nu_node[0, :n])
    h_final = hn_k(x_last, node_road[:, n], par, lam_f, mu[:, n], term[1], term[2], nu_node[0, n])
    hvals = [ca.vec(h_stage), ca.vec(h_final)]
    if lay.ns:
        hvals += [2 * lam_f * slack_weight, 2 * lam_f * _TERMINAL_SLACK_FACTOR * slack_weight]
    sp_h, src_h = _csc(lay.n_var, lay.n_var, *_hessian_pattern(lay))
    return ca.MX(sp_h, ca.vertcat(*hvals)[src_h])


def layout_of(model: SpatialModel, n_intervals: int, *, soft: bool = False,
              accel_bound: bool = True) -> Layout:
    """The layout of `transcribe`'s NLP for these arguments, without building it."""
    n_path = int(model.path.size1_out(0))
    return Layout(model.nx, model.nu, n_path if soft else 0, n_intervals, n_path, accel_bound)


def transcribe(model: SpatialModel, n_intervals: int, *, substeps: int = 1,
               soft: bool = False, slack_weight: float = 100.0,
               compile_c: bool = True, accel_bound: bool = True) -> Transcription:
    """Multiple-shooting NLP: min sum of interval costs s.t. continuity and path constraints.

    Args:
        model: the 3D or 1D spatial model.
        n_intervals: number of shooting intervals N (node count N+1).
        substeps: RK4 steps per interval.
        soft: soften the path constraints with penalised slacks (L1 + L2, one per stage
            and constraint) and add the soft terminal treatment (`TERMINAL`): `E_n(N) >=
            e_n_target - e`, and `v_price (v(N) - v_target) + v_weight (v(N) - v_target)^2`.
        slack_weight: penalty per unit slack (seconds of objective).
        compile_c: compile the stage kernels to C (cached per machine).
    """
    nx, nu, n = model.nx, model.nu, n_intervals
    lay = layout_of(model, n_intervals, soft=soft, accel_bound=accel_bound)
    nz, st = nx + nu, lay.stage
    f_k, jf_k, hk_k, p_k, hn_k, gf_k = stage_kernels(model, substeps, compile_c)
    iv, ie = model.index("v"), model.index("e_n")

    # ---- decision variables, parameters, multipliers ---------------------------------
    w = ca.MX.sym("w", lay.n_var)
    p = ca.MX.sym("p", len(ROAD) * n + len(PARAMS) + (len(TERMINAL) if soft else 0))
    body = ca.reshape(w[: st * n], st, n)
    x_last = w[st * n: st * n + nx]
    xs, us = ca.horzcat(body[:nx, :], x_last), body[nx:nz, :]
    road = ca.reshape(p[: len(ROAD) * n], len(ROAD), n)
    par = p[len(ROAD) * n: len(ROAD) * n + len(PARAMS)]
    term = p[len(ROAD) * n + len(PARAMS):] if soft else ca.MX.zeros(len(TERMINAL))
    ng_acc, ng = (n if accel_bound else 0), lay.n_g
    lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", ng)

    # ---- objective and constraints ------------------------------------------------------
    x_next, dt, dj = f_k.map(n)(xs[:, :n], us, road, par)
    turn, h = road[0, :] * road[3, :], road[3, :]  # node k's road data: module docstring
    node_road = ca.vertcat((ca.horzcat(0, turn) + ca.horzcat(turn, 0))
                           / (ca.horzcat(0, h) + ca.horzcat(h, 0)),
                           ca.horzcat(road[1:, :], road[1:, n - 1]))
    path, path_jac = p_k.map(n + 1)(xs, node_road, par)
    f = ca.sum2(dj)
    g_gap = ca.vec(x_next - xs[:, 1:])
    g_acc, v_to, v_from, ds_k = _acceleration_bound(xs[iv, :], road, par, n)
    if soft:
        slacks, e_slack = body[nz:, :], w[-1]
        # The final node has no stage of its own: it shares the last stage's slacks.
        path = path - ca.horzcat(slacks, slacks[:, n - 1])
        f = f + slack_weight * (ca.sum1(ca.sum2(slacks)) + ca.sumsqr(slacks))
        f = f + _TERMINAL_SLACK_FACTOR * slack_weight * (e_slack + e_slack ** 2)
        f = f + term[3] * (x_last[iv] - term[1]) + term[2] * (x_last[iv] - term[1]) ** 2
        g = ca.vertcat(g_gap, ca.vec(path), g_acc[:ng_acc], term[0] - x_last[ie] - e_slack)
    else:
        g = ca.vertcat(g_gap, ca.vec(path), g_acc[:ng_acc])

    # ---- gradient of f ----------------------------------------------------------------------
    stage_grad = [gf_k.map(n)(xs[:, :n], us, road, par)]
    tail = [(term[3] + 2 * term[2] * (x_last[iv] - term[1])) * ca.DM.eye(nx)[:, iv]]
    if soft:
        stage_grad.append(slack_weight * (1 + 2 * slacks))
        tail.append(_TERMINAL_SLACK_FACTOR * slack_weight * (1 + 2 * e_slack))
    grad_f = ca.densify(ca.vertcat(ca.vec(ca.vertcat(*stage_grad)), *tail))

    # ---- Jacobian of g: dense stage blocks scattered into the banded pattern -------------
    jac_z = jf_k.map(n)(xs[:, :n], us, road, par)
    values = ca.vertcat(ca.vec(jac_z), ca.vec(path_jac), ca.MX(-1),
                        ca.vec(v_to / ds_k), ca.vec(-v_from / ds_k))
    sp_j, src_j = _csc(ng, lay.n_var, *_jacobian_pattern(lay, iv, ie, ng))
    jac_g = ca.MX(sp_j, values[src_j])

    # ---- Hessian of the Lagrangian: block diagonal, upper triangle -------------------------
    hess = _hessian(lay, (hk_k, hn_k), (xs, us, x_last), (road, node_road), par, term,
                    lam_f, lam_g, ds_k, slack_weight)

    derivatives = {
        "grad_f": ca.Function("grad_f", [w, p], [f, grad_f], ["x", "p"], ["f", "grad_f_x"]),
        "jac_g": ca.Function("jac_g", [w, p], [g, jac_g], ["x", "p"], ["g", "jac_g_x"]),
        "hess_lag": ca.Function("hess_lag", [w, p, lam_f, lam_g], [hess],
                                ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"]),
    }
    out_args = (xs, node_road, par) if model.outputs.n_in() == 3 else (xs, par)
    evaluate = ca.Function("evaluate", [w, p], [dt, model.outputs.map(n + 1)(*out_args)],
                           ["w", "p"], ["dt", "y"])
    return Transcription(model, lay, {"x": w, "p": p, "f": f, "g": g}, derivatives,
                         *lay.g_bounds(), evaluate)
