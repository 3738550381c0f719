"""Model sanity: steady state vs the closed-form power balance, wind and grip conventions."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from itt_planner.model.conditions import Conditions
from itt_planner.model.dynamics import build_1d, build_3d
from itt_planner.model.params import PARAMS, ROAD, ModelParams
from itt_planner.model.rider import PRESETS
from itt_planner.model.steady import steady_speed_mps


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
    resist = rider.mass_kg * 9.81 * (rider.crr * math.cos(b) + math.sin(b))
    assert power == pytest.approx(v * (resist + k_v * v * v), rel=1e-9)
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
    road = np.array([0.0, 0.0, 0.0, 1.0])  # the 3D's path constraints ignore it
    g = np.asarray(model.path(np.array([0, 0, lean, 0, 10, 0.01, 0, 1]), road, par)).ravel()
    assert g[1] > 0  # pedalling at 25 deg of lean is infeasible (C15)
    g = np.asarray(model.path(np.array([0, 0, 0.0, 0, 10, -1.0, 0, 1]), road, par)).ravel()
    assert g[0] == pytest.approx(0.0, abs=1e-12)  # full braking uses all the grip (C16)


def test_parameter_vector_matches_names() -> None:
    assert len(ModelParams(PRESETS["climber"], Conditions()).vector()) == len(PARAMS)
    assert build_3d().ode.size1_in(2) == len(ROAD)
    assert isinstance(build_3d().ode, ca.Function)


# ---- steady speed on every branch of the cubic (issue 14, issue 18) -------------------
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from itt_planner.course.builder import build_course  # noqa: E402
from itt_planner.model.rider import Rider  # noqa: E402
from itt_planner.model.steady import speed_bound_mps  # noqa: E402
from itt_planner.ocp.guess import initial_guess, speed_guess  # noqa: E402

plausible_riders = st.builds(
    Rider, mass_kg=st.floats(50, 100), drag_area_m2=st.floats(0.18, 0.45),
    crr=st.floats(0.002, 0.01), critical_power_w=st.floats(150, 500),
    drivetrain_efficiency=st.floats(0.9, 1.0))


def _balance_residual(v: float, power: float, rider: Rider, grade: float) -> float:
    """eta P - v (m g (crr cos b + sin b) + k_v v^2), W (the E3 steady state)."""
    b = math.atan(grade)
    k_v = 0.5 * 1.23 * rider.drag_area_m2
    return (rider.drivetrain_efficiency * power
            - v * (rider.mass_kg * 9.81 * (rider.crr * math.cos(b) + math.sin(b)) + k_v * v * v))


@settings(max_examples=300, deadline=None)
@given(rider=plausible_riders, grade=st.floats(-0.25, 0.25),
       share=st.sampled_from([0.0, 0.05, 0.3, 1.0]))
def test_steady_speed_is_the_physical_root_on_every_grade(rider: Rider, grade: float,
                                                          share: float) -> None:
    """Finite, positive (when a balance exists), balances E3, and is the largest root:
    on a steep descent with little or no power that is the terminal speed."""
    power = share * rider.critical_power_w
    v = steady_speed_mps(power, rider, grade=grade)
    assert math.isfinite(v) and v >= 0
    descends = rider.crr * math.cos(math.atan(grade)) + math.sin(math.atan(grade)) < 0
    if power > 0 or descends:
        assert v > 0
        assert abs(_balance_residual(v, power, rider, grade)) < 1e-6 * max(power, 1.0) + 1e-6
        # the physical root: just above it the rider decelerates (drag wins)
        assert _balance_residual(1.001 * v, power, rider, grade) < 0
    if share == 0 and descends:  # terminal speed
        b = math.atan(grade)
        k_v = 0.5 * 1.23 * rider.drag_area_m2
        terminal = math.sqrt(-rider.mass_kg * 9.81 * (rider.crr * math.cos(b) + math.sin(b)) / k_v)
        assert v == pytest.approx(terminal, rel=1e-9)
    assert v <= speed_bound_mps(rider, Conditions(), min(grade, 0.0))


def test_steady_speed_three_real_roots_branch_reported_crash() -> None:
    """The issue's rider on -5.8 % ... -12 %: three real roots; was `math domain error`."""
    rider = Rider(mass_kg=86.0, drag_area_m2=0.273, critical_power_w=290.0)
    for grade in (-0.058, -0.069, -0.12):
        v = steady_speed_mps(50.0, rider, grade=grade)
        assert 15 < v < 30
        assert abs(_balance_residual(v, 50.0, rider, grade)) < 1e-6


def test_steady_speed_rejects_negative_power() -> None:
    with pytest.raises(ValueError, match="power"):
        steady_speed_mps(-1.0, PRESETS["paper"])


@settings(max_examples=40, deadline=None)
@given(rider=plausible_riders, grade_pct=st.floats(-25, 25))
def test_initial_guess_is_finite_on_any_grade(rider: Rider, grade_pct: float) -> None:
    """Guess code (speed profile, lean, steering) on a straight at any grade."""
    course = build_course({"segments": [
        {"type": "straight", "length_m": 300, "grade_pct": grade_pct},
        {"type": "arc", "radius_m": 15, "angle_deg": 90, "direction": "left",
         "grade_pct": grade_pct}]})
    nodes = np.linspace(0, course.length_m, 60)
    v = speed_guess(course, nodes, rider, Conditions(), 1.0, corners=True)
    assert np.all(np.isfinite(v)) and np.all(v > 0)
    x, u = initial_guess(build_3d(), course, nodes, rider, Conditions(), 1.0)
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(u))


def test_drivetrain_efficiency_scales_wheel_power_only() -> None:
    """E3 sees eta P; E9 and the reported power stay crank power."""
    lossy = Rider(drivetrain_efficiency=0.95)
    assert steady_speed_mps(400.0, lossy) < steady_speed_mps(400.0, PRESETS["paper"])
    v = steady_speed_mps(400.0, lossy)
    model = build_1d()
    par = ModelParams(lossy, Conditions()).vector()
    x = np.array([v, 400.0 / lossy.max_power_w, 1.0])
    dxds = np.asarray(model.ode(x, [0.0], np.array([0.0, 0.0, 0.0, 1.0]), par)[0]).ravel()
    assert abs(dxds[0]) * v < 0.005 * 400 / (lossy.mass_kg * v)
    assert float(model.outputs(x, par)[0]) == pytest.approx(400.0, rel=1e-9)
