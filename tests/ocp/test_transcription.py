"""Multiple shooting (`ocp.transcription`): the decision-vector layout, continuity of an
integrated trajectory, the objective as travel time, the acceleration bound, the soft
terminal condition, and the hand-scattered derivatives against CasADi's own AD."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from support.courses import hairpin

from itt_planner.model.conditions import Conditions
from itt_planner.model.dynamics import SpatialModel, build_1d, build_3d_steady_lean, rk4_step
from itt_planner.model.params import ModelParams
from itt_planner.model.rider import PRESETS
from itt_planner.ocp.guess import initial_guess
from itt_planner.ocp.mesh import build_mesh, road_data
from itt_planner.ocp.transcription import TERMINAL, Layout, Transcription, transcribe

RIDER = PRESETS["paper"]
COURSE = hairpin(straight_m=60.0)
#: Six intervals from the straight into the hairpin (curvature, slope and ds vary).
NODES = build_mesh(COURSE, 1.0, 10.0, start_m=40.0, end_m=70.0)[:7]
PAR = ModelParams(RIDER, Conditions()).vector()
assert len(NODES) == 7


def _problem(model: SpatialModel, *, soft: bool, accel: bool
             ) -> tuple[Transcription, np.ndarray, np.ndarray, np.ndarray]:
    """(transcription, parameters, guess states, guess controls) on `NODES`."""
    tr = transcribe(model, len(NODES) - 1, soft=soft, compile_c=False, accel_bound=accel)
    terminal = np.array([0.9, 9.0, 1.0, -2.0]) if soft else None
    p = tr.params(road_data(COURSE, NODES), PAR, terminal)
    if model.name == "1d":
        x, u = initial_guess(model, COURSE, NODES, RIDER, Conditions(), 9.0)
    else:
        x, u = _steady_guess(model)
    return tr, p, x, u


def _steady_guess(model: SpatialModel) -> tuple[np.ndarray, np.ndarray]:
    x = np.zeros((model.nx, len(NODES)))
    x[model.index("v")] = 9.0
    x[model.index("w_n")] = 0.3
    x[model.index("e_n")] = 0.95
    return x, np.zeros((model.nu, len(NODES) - 1))


def _integrated(tr: Transcription, x0: np.ndarray, u: np.ndarray) -> np.ndarray:
    """States obtained by integrating the model interval by interval from `x0`."""
    f = rk4_step(tr.model, 1)
    road = road_data(COURSE, NODES)
    x = np.zeros((tr.model.nx, len(NODES)))
    x[:, 0] = x0
    for k in range(len(NODES) - 1):
        x[:, k + 1] = np.asarray(f(x[:, k], u[:, k], road[:, k], PAR)[0]).ravel()
    return x


def test_layout_split_join_round_trip() -> None:
    lay = Layout(nx=3, nu=1, ns=2, n_intervals=4, n_path=2)
    rng = np.random.default_rng(1)
    x, u, s = rng.normal(size=(3, 5)), rng.normal(size=(1, 4)), rng.normal(size=(2, 4))
    w = lay.join(x, u, s, terminal_slack=0.7)
    assert w.size == lay.n_var == 4 * (3 + 1 + 2) + 3 + 1
    x2, u2, s2 = lay.split(w)
    np.testing.assert_array_equal(x2, x)
    np.testing.assert_array_equal(u2, u)
    np.testing.assert_array_equal(s2, s)
    assert w[-1] == 0.7
    k, i = np.meshgrid(np.arange(5), np.arange(3), indexing="ij")
    np.testing.assert_array_equal(w[lay.x_index(k, i)], x.T)


def test_integrated_trajectory_closes_the_gaps_and_costs_its_travel_time() -> None:
    """A trajectory of the model itself has zero continuity gaps, and with the commands
    held (u = 0: no rate penalty) the objective is exactly the time it takes."""
    tr, p, x, u = _problem(build_1d(), soft=False, accel=True)
    x = _integrated(tr, x[:, 0], u)
    w = tr.layout.join(x, u)
    fg = ca.Function("fg", [tr.nlp["x"], tr.nlp["p"]], [tr.nlp["f"], tr.nlp["g"]])
    f, g = (np.asarray(a).ravel() for a in fg(w, p))
    lay = tr.layout
    np.testing.assert_allclose(g[: lay.n_gap], 0.0, atol=1e-12)
    dt = np.asarray(tr.evaluate(w, p)[0])
    assert f[0] == pytest.approx(float(np.sum(dt)), rel=1e-12)
    # ~30 m at ~9 m/s.
    assert 2.0 < f[0] < 5.0
    # Physical: the tyres and the acceleration bound hold along a real ride.
    assert np.all(g[lay.accel_rows] <= 0) and np.all(g[lay.n_gap: lay.accel_rows.start] <= 0)
    assert np.all(g <= tr.ubg + 1e-12) and np.all(g >= tr.lbg - 1e-12)


def test_acceleration_bound_catches_speed_from_nothing() -> None:
    """Speed gained faster than tyres and gravity allow (the issue-18 artefact) is
    infeasible, whatever the integrator says."""
    tr, p, x, u = _problem(build_1d(), soft=False, accel=True)
    x = _integrated(tr, x[:, 0], u)
    iv = tr.model.index("v")
    ds = np.diff(NODES)[2]
    x[iv, 3] = np.sqrt(x[iv, 2] ** 2 + 2 * 1.2 * 9.81 * ds)  # 1.2 g on a flat road
    g = np.asarray(ca.Function("g", [tr.nlp["x"], tr.nlp["p"]], [tr.nlp["g"]])(
        tr.layout.join(x, u), p)).ravel()
    acc = g[tr.layout.accel_rows]
    assert acc[2] > 0 and np.all(np.delete(acc, [2, 3]) <= 0)


def test_soft_terminal_condition() -> None:
    """Soft: E_n(N) >= target - e, and the speed over the end priced (`TERMINAL`)."""
    tr, p, x, u = _problem(build_3d_steady_lean(), soft=True, accel=False)
    assert len(TERMINAL) == 4 and tr.layout.ns == 2
    fg = ca.Function("fg", [tr.nlp["x"], tr.nlp["p"]], [tr.nlp["f"], tr.nlp["g"]])
    ie, iv = tr.model.index("e_n"), tr.model.index("v")
    x = x.copy()
    x[ie, -1] = 0.85  # 0.05 below the target 0.9
    f0, g0 = (np.asarray(a).ravel() for a in fg(tr.layout.join(x, u), p))
    assert g0[-1] == pytest.approx(0.9 - 0.85)  # violated without slack
    f1, g1 = (np.asarray(a).ravel() for a in fg(tr.layout.join(x, u, terminal_slack=0.05), p))
    assert g1[-1] == pytest.approx(0.0, abs=1e-12)
    assert f1[0] > f0[0]  # the slack costs
    x[iv, -1] += 0.1  # 0.1 m/s more over the end: worth 2 s per m/s, minus the pull
    f2 = float(np.asarray(fg(tr.layout.join(x, u), p)[0]).ravel()[0])
    pull = 1.0 * ((9.1 - 9.0) ** 2 - (9.0 - 9.0) ** 2)
    assert f2 - f0[0] == pytest.approx(-2.0 * 0.1 + pull, rel=1e-6, abs=1e-6)


@pytest.mark.parametrize(("kind", "soft", "accel"), [
    ("1d", False, True), ("steady", True, False), ("steady", False, True)])
def test_scattered_derivatives_equal_casadi_ad(kind: str, soft: bool, accel: bool) -> None:
    """The per-stage kernels scattered into the banded patterns give exactly what CasADi
    computes by differentiating the whole NLP (gradient, Jacobian, Lagrangian Hessian)."""
    model = build_1d() if kind == "1d" else build_3d_steady_lean()
    tr, p, x, u = _problem(model, soft=soft, accel=accel)
    rng = np.random.default_rng(2)
    lay = tr.layout
    w = lay.join(x, u + 0.1 * rng.standard_normal(u.shape),
                 0.01 * rng.random((lay.ns, lay.n_intervals)), 0.02)
    w = w + 1e-3 * rng.standard_normal(w.size)
    lam_f = 0.7
    lam_g = rng.standard_normal(tr.lbg.size)
    wx, px = tr.nlp["x"], tr.nlp["p"]
    lam_g_sym = ca.MX.sym("lam_g", tr.lbg.size)
    lag = lam_f * tr.nlp["f"] + ca.dot(lam_g_sym, tr.nlp["g"])
    ad = ca.Function("ad", [wx, px, lam_g_sym], [
        ca.gradient(tr.nlp["f"], wx), ca.jacobian(tr.nlp["g"], wx), ca.hessian(lag, wx)[0]])
    grad_ad, jac_ad, hess_ad = (np.asarray(ca.densify(a)) for a in ad(w, p, lam_g))
    d = tr.derivatives
    grad = np.asarray(d["grad_f"](w, p)[1]).ravel()
    jac = np.asarray(ca.densify(d["jac_g"](w, p)[1]))
    hess = np.asarray(ca.densify(d["hess_lag"](w, p, lam_f, lam_g)))
    np.testing.assert_allclose(grad, grad_ad.ravel(), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(jac, jac_ad, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(hess, np.triu(hess_ad), rtol=1e-8, atol=1e-8)
