"""Model sanity: steady state vs the closed-form power balance, wind and grip conventions."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from itt_planner.conditions import Conditions
from itt_planner.model import PARAMS, ROAD, ModelParams, build_1d, build_3d, steady_speed_mps
from itt_planner.rider import PRESETS


def _x3d(v: float, w_n: float) -> np.ndarray:
    return np.array([0, 0, 0, 0, v, w_n, 0, 1.0])


@pytest.mark.parametrize("grade", [0.0, 0.05])
def test_steady_speed_closed_form_zeroes_acceleration(grade: float) -> None:
    rider = PRESETS["paper"]
    power = 400.0
    v = steady_speed_mps(power, rider, grade=grade)
    # Martin et al. (1998) balance: P = v (m g (crr cos b + sin b) + k_v v^2)
    b = math.atan(grade)
    k_v = 0.5 * 1.23 * rider.drag_area_m2
    assert power == pytest.approx(v * (rider.mass_kg * 9.81 * (rider.crr * math.cos(b) + math.sin(b))
                                       + k_v * v * v), rel=1e-9)
    par = ModelParams(rider, Conditions()).vector()
    road = np.array([0.0, b, 0.0, 1.0])
    for model, x in ((build_3d(), _x3d(v, power / rider.max_power_w)),
                     (build_1d(), np.array([v, power / rider.max_power_w, 1.0]))):
        dxds = np.asarray(model.ode(x, np.zeros(model.nu), road, par)[0]).ravel()
        # dv/ds = 0 within the smoothing of max(W_n, 0) (~1 W of 400 W).
        assert abs(dxds[model.index("v")]) * v < 0.005 * power / (rider.mass_kg * v)


def test_head_wind_slows_and_tail_wind_helps() -> None:
    rider, model = PRESETS["paper"], build_1d()
    road_east = np.array([0.0, 0.0, 0.0, 1.0])  # heading East
    x = np.array([12.0, 0.2, 1.0])

    def accel(cond: Conditions) -> float:
        return float(model.ode(x, [0.0], road_east, ModelParams(rider, cond).vector())[0][0])

    calm = accel(Conditions())
    head = accel(Conditions.from_meteo(wind_kmh=20, wind_from_deg=90))  # from the East
    tail = accel(Conditions.from_meteo(wind_kmh=20, wind_from_deg=270))
    assert head < calm < tail


def test_steady_turn_lean_matches_grip_relation() -> None:
    """E5: in a steady turn tan(phi) = -(v^2 tan(delta)/L)/g; lean is towards the turn."""
    rider, model = PRESETS["paper"], build_3d()
    v, radius = 10.0, 20.0
    delta = math.atan(rider.wheelbase_m / radius)
    phi = -math.atan(v * v / radius / 9.81)
    x = np.array([0, 0, phi, 0, v, 0.2, delta / rider.steer_max_rad, 1.0])
    road = np.array([1 / radius, 0.0, 0.0, 1.0])
    dxds = np.asarray(model.ode(x, [0, 0], road, ModelParams(rider, Conditions()).vector())[0])
    assert abs(dxds[3, 0]) < 1e-9  # no roll acceleration
    assert abs(dxds[1, 0]) < 1e-9  # follows the road's curvature
    y = np.asarray(model.outputs(x, ModelParams(rider, Conditions()).vector())).ravel()
    assert y[2] == pytest.approx(v * v / radius)


def test_pedalling_gate_and_friction_ellipse() -> None:
    rider, model = PRESETS["paper"], build_3d()
    par = ModelParams(rider, Conditions()).vector()
    lean = math.radians(25)
    g = np.asarray(model.path(np.array([0, 0, lean, 0, 10, 0.01, 0, 1]), par)).ravel()
    assert g[1] > 0  # pedalling at 25 deg of lean is infeasible (C15)
    g = np.asarray(model.path(np.array([0, 0, 0.0, 0, 10, -1.0, 0, 1]), par)).ravel()
    assert g[0] == pytest.approx(0.0, abs=1e-12)  # full braking uses all the grip (C16)


def test_parameter_vector_matches_names() -> None:
    assert len(ModelParams(PRESETS["climber"], Conditions()).vector()) == len(PARAMS)
    assert build_3d().ode.size1_in(2) == len(ROAD)
    assert isinstance(build_3d().ode, ca.Function)
