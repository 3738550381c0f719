"""Closed-loop virtual rider: sensors, the time-domain 3D model against the plan, the
scenarios, replanned vs open loop vs even CP, and `itt-planner simulate`.

The default closed-loop runs use the ~2.8 km technical test course (`hairpin_course`)
with a 400 m horizon replanned every 2 s, so they take seconds of solver time each;
the verona-like race and the remaining scenarios are `slow` (and in
bench/bench_closed_loop.py)."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from support.hairpin_fixtures import PLAN_CONDITIONS, RIDER
from typer.testing import CliRunner

from itt_planner.cli import app
from itt_planner.course.geometry import Course
from itt_planner.errors import RiderError
from itt_planner.live.course_replan import CourseReplanSettings
from itt_planner.live.cp_monitor import CpMonitorSettings
from itt_planner.live.engine import EngineSettings
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed
from itt_planner.model.conditions import Conditions
from itt_planner.ocp.cache import load_or_solve
from itt_planner.ocp.course_settings import OcpSettings
from itt_planner.ocp.horizon import HorizonPlanner
from itt_planner.ocp.horizon_settings import HorizonSettings
from itt_planner.ocp.plan import Plan
from itt_planner.sim import (
    Policy,
    RiderBehaviour,
    Sensors,
    SensorSettings,
    compare_policies,
    planning_conditions,
    simulate_ride,
)

FAST_HORIZON = HorizonSettings(horizon_m=400.0, n_intervals=50, max_wall_time_s=30.0)
#: Replan every 2 s; no overrun judged on a loaded 2-core machine; the rest of the
#: course re-solved while it is longer than the 400 m horizon.
FAST_ENGINE = EngineSettings(replan_period_s=2.0, max_solve_time_s=30.0,
                             course_replan=CourseReplanSettings(min_remaining_m=400.0))


def _compare(course: Course, plan: Plan, scenario: str) -> dict[str, Any]:
    return compare_policies(course, RIDER, plan, scenario=scenario, seed=1,
                            engine_settings=FAST_ENGINE,
                            planner=HorizonPlanner(course, RIDER, plan,
                                                   conditions=PLAN_CONDITIONS,
                                                   settings=FAST_HORIZON))


def test_sensor_model(course: Course) -> None:
    """1 Hz GPS with ~3 m error per axis, a dropout, 1 Hz wheel speed and power; power
    meters read zero while braking."""
    settings = SensorSettings(dropouts=((100.0, 60.0),))
    sensors = Sensors(course, settings, np.random.default_rng(0))
    errors, samples = [], []
    for k in range(3000):
        t = 0.1 * k
        s = 10.0 * t % course.length_m
        power = -300.0 if 50 <= t < 60 else 400.0
        out = sensors.sample(t, s, 0.0, 10.0, power)
        samples += out
        for smp in out:
            if isinstance(smp, GpsFix):
                x, y, _ = course.from_geodetic(np.asarray(smp.lat_deg), np.asarray(smp.lon_deg),
                                               np.asarray(smp.alt_m))
                xt, yt, _ = course.enu_at(s, 0.0)
                errors.append((float(x - xt), float(y - yt)))
    gps = [x for x in samples if isinstance(x, GpsFix)]
    assert len(gps) == 300 - 60  # 1 Hz minus the 60 s dropout
    assert not any(100.0 <= g.stamp_s < 160.0 for g in gps)
    assert np.std(np.array(errors)) == pytest.approx(3.0, rel=0.35)
    powers = [x for x in samples if isinstance(x, PowerReading)]
    assert len(powers) == 300 and all(p.power_w == 0.0 for p in powers if 50 <= p.stamp_s < 60)
    assert len([x for x in samples if isinstance(x, WheelSpeed)]) == 300
    stamps = [x.stamp_s for x in samples]
    assert stamps == sorted(stamps)


def test_planning_conditions_use_the_riders_lateral_grip() -> None:
    """The planner believes the truth's road and air with the lateral grip the rider uses."""
    truth = Conditions(mu_x=0.9, mu_y=0.8, wind_speed_mps=2.0, wind_from_rad=1.0)
    belief = planning_conditions(truth, RiderBehaviour(grip_lateral=0.9))
    assert belief.mu_y == pytest.approx(0.72)
    assert (belief.mu_x, belief.wind_speed_mps, belief.wind_from_rad) == (0.9, 2.0, 1.0)
    for bad in (0.0, 1.5, math.nan):
        with pytest.raises(RiderError):
            truth.with_lateral_grip(bad)


def test_time_domain_model_reproduces_the_plan(course: Course, plan: Plan) -> None:
    """Following the full-course plan in time (lag, noise, path-following controller),
    the 3D model ends within 1 % of the OCP's time and stays near the planned line.
    (Measured +0.36 to +0.61 % over seeds 1-4 with the plan solved for the grip the rider
    uses, 0.3 m RMS off the planned line; +1.6 to +1.8 % and 2-5 m off in the hairpins
    while the rider's steering fed forward the road's curvature instead of the line's.)"""
    res = simulate_ride(course, RIDER, plan, policy=Policy.OPEN_LOOP, seed=1)
    assert res.finish_time_s == pytest.approx(plan.finish_time_s, rel=0.01)
    assert np.sqrt(np.mean((res.n_m - plan.at("n_m", res.s_m)) ** 2)) < 0.5
    err = res.n_m - plan.at("n_m", res.s_m)
    assert np.sqrt(np.mean(err ** 2)) < 1.2
    # The speed trace follows the plan's, corners included.
    v_err = res.v_mps - plan.at("v_mps", res.s_m)
    assert np.median(np.abs(v_err[res.t_s > 5.0])) < 0.6
    assert np.all(np.diff(res.s_m) >= 0)


def test_scenarios_change_the_truth_not_the_plan(course: Course, plan: Plan) -> None:
    nominal = simulate_ride(course, RIDER, plan, policy=Policy.EVEN_CP, seed=1)
    weak = simulate_ride(course, RIDER, plan, policy=Policy.EVEN_CP, seed=1,
                         scenario="cp-overestimated")
    windy = simulate_ride(course, RIDER, plan, policy=Policy.EVEN_CP, seed=1,
                          scenario="headwind")
    # Even pacing at the believed CP drains a rider whose true CP is 5 % lower ...
    assert weak.w_prime_j[-1] < nominal.w_prime_j[-1] - 1000.0
    # ... and a head wind on the second half only slows the second half.
    half = course.length_m / 2
    t_half = [np.interp(half, r.s_m, r.t_s) for r in (nominal, windy)]
    assert t_half[1] == pytest.approx(t_half[0], abs=0.05)
    assert windy.finish_time_s > nominal.finish_time_s + 3.0


@pytest.mark.parametrize("scenario", ["nominal", "hot-start", "headwind"])
@pytest.mark.parametrize("policy", [Policy.OPEN_LOOP, Policy.EVEN_CP])
def test_truth_respects_grip(course: Course, plan: Plan, policy: str, scenario: str) -> None:
    """The simulated truth never uses more than the friction ellipse C16 allows, in the
    hairpin, the S-bend and on the way in and out of them (lean transients included),
    whatever the rider follows (the replanned rides: in the compare tests below)."""
    res = simulate_ride(course, RIDER, plan, policy=policy, scenario=scenario, seed=1)
    assert math.isfinite(res.finish_time_s)
    assert res.friction_use.max() <= 1.0 + 1e-3


def test_nominal_replanned_close_to_the_optimum(course: Course, plan: Plan) -> None:
    """Belief = truth (the plan and the horizon are solved for the grip the rider uses).
    Within the issue's 1 % of that optimum (measured +0.26 to +0.52 % over seeds 1-4):
    the rider stays on the plan, so the advice is the plan (engine: event-triggered
    replanning), and the rider rides it exactly as the blind plan (margin 0.000 s on
    seeds 1-4): asserted is no more than 0.5 s behind it."""
    out = _compare(course, plan, "nominal")
    assert out["plan_for_rider_grip"]
    replanned = out["replanned"]
    assert replanned["finish_time_s"] <= 1.01 * plan.finish_time_s
    assert out["margins"]["replanned_vs_open_loop_s"] > -0.5
    for policy in ("replanned", "open_loop", "even_cp"):
        assert out[policy]["w_prime_min_j"] >= 0.0
        assert out[policy]["max_friction_use"] <= 1.0 + 1e-3
    assert out["margins"]["replanned_vs_even_cp_s"] > 0
    lat = out["replan_latency_s"]
    assert 0 <= lat["median"] <= lat["p95"] <= lat["max"]


def test_hot_start_replanned_ties_open_loop_on_the_hairpin(course: Course, plan: Plan) -> None:
    """The rider burns W' over the first third; the blind plan then runs dry and
    finishes with W' it could not place, the replanned ride re-budgets it (the horizon,
    then the rest of the course re-solved from the rider's state). On this short course
    there is little to re-budget: the replanned ride ties the blind plan, and which
    seed comes out ahead depends on the blind plan's local optimum. Measured on seeds
    1-4 (2026-12-02, bench/RESULTS.md): plan 184.98 s (the cold guess) -0.228, 0.000,
    -0.173, +0.145 s; 184.05 s (arc guess, centre line) -0.093, 0.000, +0.008, +0.022;
    184.08 s (arc guess on the line) +0.100, 0.000, -0.229, -0.032. So a tie within
    0.3 s (0.16 %) is asserted. The "regression" of 2026-12-01 (seed 1 -0.226 s instead
    of -0.009 s after the plan/horizon changes) lies within that spread: with the same
    replanning code only the blind plan's guess moved seed 1 from -0.228 to +0.100 s.
    On verona-like the replanned ride is ahead (`test_verona_like_hot_start`)."""
    out = _compare(course, plan, "hot-start")
    assert out["replanned"]["w_prime_min_j"] >= 0.0
    assert out["replanned"]["max_friction_use"] <= 1.0 + 1e-3
    assert out["margins"]["replanned_vs_open_loop_s"] > -0.3
    assert out["open_loop"]["w_prime_end_j"] > out["replanned"]["w_prime_end_j"]


def test_cp_overestimated_is_detected(course: Course, plan: Plan) -> None:
    """True CP 5 % below the belief (418 W vs 440 W): the engine sees the rider fail to
    hold advice above CP, refits CP from the power history to within a few W of the
    truth and replans with it. It does NOT beat the blind plan here (measured -0.000,
    -0.050, -0.000, +0.001 s over seeds 1-4): both riders run dry before anything
    reveals the lower CP (the refit comes with the last 10 % of this course to go), and
    from there on both ride at the true CP; bench/RESULTS.md, closed-loop section 7).
    The refit's confirmation (`CpMonitorSettings.confirm_s`: no surge to CP in the next
    10 s) would outlast this 3-minute course: it is off here, and tested in
    tests/live/test_cp_monitor.py."""
    at_once = dataclasses.replace(FAST_ENGINE, cp_monitor=CpMonitorSettings(confirm_s=0.0))
    out = compare_policies(course, RIDER, plan, scenario="cp-overestimated", seed=1,
                           engine_settings=at_once,
                           planner=HorizonPlanner(course, RIDER, plan,
                                                  conditions=PLAN_CONDITIONS,
                                                  settings=FAST_HORIZON))
    assert out["replanned"]["cp_in_use_w"] == pytest.approx(0.95 * RIDER.critical_power_w,
                                                            rel=0.02)
    assert out["margins"]["replanned_vs_even_cp_s"] > 0.0
    for policy in ("replanned", "open_loop", "even_cp"):
        assert out[policy]["w_prime_min_j"] >= 0.0
        assert out[policy]["max_friction_use"] <= 1.0 + 1e-3


@pytest.mark.slow
def test_headwind(course: Course, plan: Plan) -> None:
    """W' stays >= 0 and the replanned ride beats even pacing."""
    out = _compare(course, plan, "headwind")
    for policy in ("replanned", "open_loop", "even_cp"):
        assert out[policy]["w_prime_min_j"] >= 0.0
    assert out["margins"]["replanned_vs_even_cp_s"] > 0.0


@pytest.mark.slow
def test_verona_like_nominal(request: pytest.FixtureRequest) -> None:
    """The whole verona-like race in closed loop (1 km horizon, replan every 1 s), the
    plan solved for the grip the rider uses. Measured 2026-11-30 (evening) with the
    horizon's wall cap raised to 30 s (no load-dependent fallbacks): replanned 1267.86 /
    1267.73 s (seeds 0 / 1) vs that optimum 1261.93 s (+0.47 / +0.46 %; the blind plan
    +0.49 / +0.44 %). With the default 0.8 s wall cap the horizon's solves are
    load-dependent, so asserted is what holds with room (W' >= 0, within 3 %, far ahead
    of even pacing). See bench/RESULTS.md."""
    from itt_planner.course.loader import load_course

    course = load_course("verona-like")
    plan = load_or_solve(course, RIDER, PLAN_CONDITIONS, OcpSettings(), "3d",
                         cache_dir=request.config.cache.mkdir("itt_plans"))
    out = compare_policies(course, RIDER, plan, scenario="nominal", seed=0,
                           engine_settings=EngineSettings(max_solve_time_s=30.0))
    assert out["replanned"]["finish_time_s"] <= 1.03 * plan.finish_time_s
    assert out["replanned"]["w_prime_min_j"] >= 0.0
    assert out["margins"]["replanned_vs_even_cp_s"] > 0.0


@pytest.mark.slow
def test_verona_like_hot_start(request: pytest.FixtureRequest) -> None:
    """The whole verona-like race after a hot start (the first 2 km at 115 % of the
    plan's power, advice ignored): the replanned ride beats the blind plan, which runs
    dry on the climb at km 7-8. Measured 2026-11-30 (evening), seeds 0 / 1: +1.68 /
    +2.16 s (1270.63 / 1269.05 s vs 1272.32 / 1271.20 s). Horizon wall cap 30 s, so the
    result does not depend on the machine's load."""
    from itt_planner.course.loader import load_course

    course = load_course("verona-like")
    plan = load_or_solve(course, RIDER, PLAN_CONDITIONS, OcpSettings(), "3d",
                         cache_dir=request.config.cache.mkdir("itt_plans"))
    planner = HorizonPlanner(course, RIDER, plan, conditions=PLAN_CONDITIONS,
                             settings=HorizonSettings(max_wall_time_s=30.0))
    out = compare_policies(course, RIDER, plan, scenario="hot-start", seed=0,
                           engine_settings=EngineSettings(max_solve_time_s=30.0),
                           planner=planner)
    assert out["margins"]["replanned_vs_open_loop_s"] > 0.0
    assert out["replanned"]["w_prime_min_j"] >= 0.0
    assert out["replanned"]["max_friction_use"] <= 1.0 + 1e-3


def test_cli_simulate_json(tmp_path: Path) -> None:
    """The CLI on a 700 m course (a straight and one hairpin), so the plan and the ~40
    replans take seconds."""
    spec = {"name": "mini", "segments": [
        {"type": "straight", "length_m": 300, "grade_pct": 2},
        {"type": "clothoid", "length_m": 10, "radius_m": 15, "direction": "left"},
        {"type": "arc", "angle_deg": 150, "radius_m": 15, "direction": "left"},
        {"type": "clothoid", "length_m": 10},
        {"type": "straight", "length_m": 330}]}
    path = tmp_path / "mini.yaml"
    path.write_text(yaml.safe_dump(spec))
    result = CliRunner().invoke(app, [
        "simulate", "--course", str(path), "--rider", "paper", "--scenario", "hot-start",
        "--horizon-m", "300", "--replan-period-s", "2", "--cache-dir", str(tmp_path / "c"),
        "--json"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    for policy in ("replanned", "open_loop", "even_cp"):
        assert set(out[policy]) >= {"finish_time_s", "w_prime_min_j", "w_prime_end_j"}
        assert math.isfinite(out[policy]["finish_time_s"])
    assert set(out["replan_latency_s"]) == {"median", "p95", "max"}
    assert out["plan_finish_time_s"] > 0
    bad = CliRunner().invoke(app, ["simulate", "--course", str(path), "--scenario", "storm",
                                   "--cache-dir", str(tmp_path / "c"), "--json"])
    assert bad.exit_code == 1 and "error" in json.loads(bad.stdout)
