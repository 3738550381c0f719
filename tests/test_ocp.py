"""Full-course OCP: physics sanity on a hairpin course, consistency, bad inputs, caching."""

from __future__ import annotations

import math

import numpy as np
import pytest

from itt_planner.conditions import Conditions
from itt_planner.course import Course, GeoOrigin
from itt_planner.errors import RiderError, SolveError
from itt_planner.model import steady_speed_mps
from itt_planner.ocp import OcpSettings, solve_plan
from itt_planner.plan import Plan, corner_table, splits
from itt_planner.plan_cache import load_or_solve
from itt_planner.rider import PRESETS, Rider


def hairpin(straight_m: float = 300.0, radius_m: float = 12.0, width_m: float = 4.0) -> Course:
    """A straight, a 180 deg hairpin of `radius_m`, a straight back (flat)."""
    a = np.arange(0.0, straight_m, 1.0)
    th = np.linspace(-np.pi / 2, np.pi / 2, int(np.pi * radius_m) + 1)[1:]
    b = np.arange(1.0, straight_m, 1.0)
    x = np.concatenate([a, straight_m + radius_m * np.cos(th), straight_m - b])
    y = np.concatenate([0 * a, radius_m + radius_m * np.sin(th), np.full_like(b, 2 * radius_m)])
    return Course.from_centerline("hairpin", x, y, np.zeros_like(x), origin=GeoOrigin(45, 11, 0),
                                  width_left_m=width_m, width_right_m=width_m, synthetic=True)


def straight(length_m: float = 1500.0) -> Course:
    x = np.arange(0.0, length_m, 1.0)
    return Course.from_centerline("straight", x, 0 * x, 0 * x, origin=GeoOrigin(45, 11, 0))


@pytest.fixture(scope="module")
def hairpin_plan() -> Plan:
    return solve_plan(hairpin(), PRESETS["paper"], model="3d")


def test_hairpin_physics(hairpin_plan: Plan) -> None:
    p, rider = hairpin_plan, PRESETS["paper"]
    assert p.meta["success"], p.solver_status
    apex = hairpin().corners[0].apex_s_m
    before = (p.s_m > apex - 150) & (p.s_m < apex)
    assert p.w_n[before].min() < 0  # brakes before the hairpin
    assert np.degrees(np.abs(p.phi_rad).max()) <= math.degrees(math.atan(1.0)) + 2
    assert p.friction_use.max() <= 1 + 1e-3  # C16
    assert np.all(np.abs(p.n_m) <= 4.0 - 0.5 + 1e-6)  # C11 with the margin
    leaning = np.abs(p.phi_rad) > math.radians(20.5)
    assert np.all(p.power_w[leaning] <= 5.0)  # C15: no pedalling beyond 20 deg
    assert p.w_prime_j.min() >= -0.01  # C12 (solver tolerance: 1e-8 of E_0)
    assert p.w_prime_j[-1] <= 0.02 * rider.w_prime_j
    inside = (p.s_m > apex - 20) & (p.s_m < apex + 20)
    assert np.abs(p.n_m[inside]).max() > 2.0  # cuts the apex


def test_corner_table_and_splits(hairpin_plan: Plan, tmp_path) -> None:
    rows = corner_table(hairpin_plan, hairpin().corners)
    assert len(rows) == 1 and rows[0].braking_s_m is not None
    assert rows[0].apex_speed_mps < rows[0].entry_speed_mps
    sp = splits(hairpin_plan, 200.0)
    assert sp[-1]["elapsed_s"] == pytest.approx(hairpin_plan.finish_time_s)
    assert sum(r["split_s"] for r in sp) == pytest.approx(hairpin_plan.finish_time_s)
    back = Plan.load(hairpin_plan.save(tmp_path / "p.plan.npz"))
    assert back.finish_time_s == pytest.approx(hairpin_plan.finish_time_s)


def test_steady_state_matches_power_balance() -> None:
    """Flat straight, CP equal to the whole ride: speed settles at the closed form."""
    rider = PRESETS["paper"]
    p = solve_plan(straight(3000.0), rider, model="1d")
    v_ss = steady_speed_mps(rider.critical_power_w, rider)
    mid = (p.s_m > 1500) & (p.s_m < 2500)
    power = np.mean(p.power_w[mid])
    assert np.mean(p.v_mps[mid]) == pytest.approx(steady_speed_mps(power, rider), rel=0.005)
    assert v_ss > 0


def test_1d_and_3d_agree_on_a_straight() -> None:
    c = straight()
    t3 = solve_plan(c, PRESETS["paper"], model="3d").finish_time_s
    t1 = solve_plan(c, PRESETS["paper"], model="1d").finish_time_s
    assert t3 == pytest.approx(t1, rel=0.01)


def test_wet_and_head_wind_are_slower(hairpin_plan: Plan) -> None:
    wet = solve_plan(hairpin(), PRESETS["paper"], Conditions(mu_x=0.6, mu_y=0.6))
    assert wet.meta["success"], wet.solver_status
    assert wet.finish_time_s > hairpin_plan.finish_time_s
    assert np.abs(wet.phi_rad).max() <= math.atan(0.6) + math.radians(2)
    # The first straight runs East: a wind from the East is a head wind there.
    windy = solve_plan(straight(), PRESETS["paper"], Conditions.from_meteo(wind_kmh=20,
                                                                          wind_from_deg=90))
    calm = solve_plan(straight(), PRESETS["paper"])
    assert windy.finish_time_s > calm.finish_time_s


def test_bad_settings_end_cleanly() -> None:
    with pytest.raises(RiderError):
        Rider(critical_power_w=0.0)
    with pytest.raises(SolveError) as err:
        solve_plan(hairpin(width_m=0.4), PRESETS["paper"])
    assert err.value.status == "invalid_input"
    # A 30 % wall: the solver stops at its caps with a status, no hang, no exception.
    x = np.arange(0.0, 400.0, 1.0)
    wall = Course.from_centerline("wall", x, 0 * x, 0.3 * x, origin=GeoOrigin(45, 11, 0))
    weak = Rider(name="weak", critical_power_w=60.0, max_power_w=200.0, w_prime_j=2000.0)
    plan = solve_plan(wall, weak, settings=OcpSettings(max_iter=60, max_cpu_time_s=20.0), model="1d")
    assert isinstance(plan.solver_status, str)


def test_plan_cache_round_trip(tmp_path) -> None:
    c = straight(600.0)
    first = load_or_solve(c, PRESETS["paper"], model="1d", cache_dir=tmp_path)
    assert len(list(tmp_path.glob("*.plan.npz"))) == 1
    again = load_or_solve(c, PRESETS["paper"], model="1d", cache_dir=tmp_path)
    assert again.finish_time_s == pytest.approx(first.finish_time_s)
    other = load_or_solve(c, PRESETS["climber"], model="1d", cache_dir=tmp_path)
    assert other.finish_time_s != pytest.approx(first.finish_time_s)
