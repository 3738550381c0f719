"""E3 on the slope of the rider's own path (issue 18): the road is level across its
width, so a line inside a bend climbs the same height over a shorter path (steeper) and
one outside over a longer path (flatter); a rider coasting up a bend at any offset
trades the same kinetic energy for the same height."""

from __future__ import annotations

import math
from collections.abc import Callable

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.dynamics import (
    SpatialModel,
    build_3d,
    build_3d_steady_lean,
    path_slope_rad,
    steady_lean_rad,
)
from itt_planner.model.params import PARAMS, ModelParams
from itt_planner.model.rider import PRESETS


def test_path_slope_on_a_straight_road_is_the_road_slope() -> None:
    beta = math.atan(0.07)
    for n in (-3.0, 0.0, 2.5):
        assert float(path_slope_rad(beta, n, 0.0, 0.0)) == pytest.approx(beta, rel=1e-12)


@pytest.mark.parametrize("n_m", [-3.0, 3.0])
def test_path_slope_in_a_bend_scales_with_the_path_length(n_m: float) -> None:
    """Radius 20 m, offset n (positive left, a left bend): tan scales by 1/(1 - n/R)."""
    radius, grade = 20.0, 0.06
    got = math.tan(float(path_slope_rad(math.atan(grade), n_m, 0.0, 1 / radius)))
    assert got == pytest.approx(grade / (1 - n_m / radius), rel=1e-12)
    if n_m > 0:  # inside: shorter and steeper
        assert got > grade
    else:
        assert got < grade


def test_path_slope_of_an_angled_line_scales_with_cos_alpha() -> None:
    grade, alpha = -0.05, 0.3
    got = math.tan(float(path_slope_rad(math.atan(grade), 0.0, alpha, 0.0)))
    assert got == pytest.approx(grade * math.cos(alpha), rel=1e-12)


def test_path_slope_casadi_and_numpy_agree() -> None:
    beta, n, alpha, kappa = np.array([0.05, -0.08]), np.array([1.5, -2.0]), \
        np.array([0.1, -0.2]), np.array([0.02, -0.05])
    sym = ca.SX.sym("a", 4)
    f = ca.Function("f", [sym], [path_slope_rad(sym[0], sym[1], sym[2], sym[3])])
    numeric = path_slope_rad(beta, n, alpha, kappa)
    for i in range(2):
        assert float(f([beta[i], n[i], alpha[i], kappa[i]])) == pytest.approx(numeric[i],
                                                                              rel=1e-12)


def _coast_up_a_bend(model: SpatialModel, n_m: float, *, radius_m: float = 20.0,
                     grade: float = 0.08, length_m: float = 40.0, v0_mps: float = 12.0
                     ) -> tuple[float, float]:
    """(Delta of v^2/2, g Delta z) (J/kg) of a rider coasting `length_m` of centre line up
    a left bend at a constant offset, steering the steady turn that holds it (alpha = 0),
    with rolling resistance and drag set to zero, and no tyre force (the smoothed
    max(W_n, 0) of E3 leaves ~0.5 W of pedalling and 0.3 N of braking at W_n = 0): what
    is left is gravity alone."""
    rider = PRESETS["paper"]
    par = ModelParams(rider, Conditions()).vector()
    for name, value in (("k_v", 0.0), ("crr", 0.0), ("mu_x", 0.0), ("p_max", 1e-6)):
        par[PARAMS.index(name)] = value
    kappa = 1 / radius_m
    road = [kappa, math.atan(grade), 0.0, 1.0]
    # yaw rate v tan(delta)/L = kappa s_dot = kappa v / (1 - n kappa): alpha stays 0.
    delta_n = math.atan(rider.wheelbase_m * kappa / (1 - n_m * kappa)) / rider.steer_max_rad
    x0 = {"n": n_m, "alpha": 0.0, "v": v0_mps, "w_n": 0.0, "delta_n": delta_n, "e_n": 1.0,
          "phi": float(steady_lean_rad(np.asarray(v0_mps ** 2 * kappa / (1 - n_m * kappa)))),
          "phi_dot": 0.0}

    def rhs(_s: float, x: np.ndarray) -> np.ndarray:
        return np.asarray(model.ode(x, np.zeros(model.nu), road, par)[0]).ravel()

    sol = solve_ivp(rhs, (0.0, length_m), [x0[name] for name in model.states],
                    rtol=1e-10, atol=1e-10)
    assert sol.success
    iv, i_n = model.index("v"), model.index("n")
    assert abs(sol.y[i_n, -1] - n_m) < 1e-3  # the rider held the line
    return 0.5 * (sol.y[iv, -1] ** 2 - v0_mps ** 2), GRAVITY_MPS2 * grade * length_m


@pytest.mark.parametrize("build", [build_3d, build_3d_steady_lean])
@pytest.mark.parametrize("n_m", [-3.0, 0.0, 3.0])
def test_coasting_up_a_bend_trades_kinetic_energy_for_the_road_height(
        build: Callable[[], SpatialModel], n_m: float) -> None:
    """Energy balance: the work of gravity along the path is m g dh at any offset.
    E3's gravity is `m g sin(beta)` per metre of the (horizontal, model.md section 1)
    path, so that work is `m g dh cos(beta_path)` exactly, within 0.5 % of m g dh on
    this 8 % climb. With the centre line's slope on the rider's line (the bug) the
    inside line (3 m at R 20 m) lost 15 % less speed than its height gain needs, the
    outside one 15 % more."""
    kinetic, potential = _coast_up_a_bend(build(), n_m)
    beta_path = float(path_slope_rad(math.atan(0.08), n_m, 0.0, 1 / 20.0))
    assert -kinetic == pytest.approx(potential * math.cos(beta_path), rel=1e-6)
    assert kinetic + potential == pytest.approx(0.0, abs=0.005 * potential)
