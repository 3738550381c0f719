"""Full-course OCP: physics sanity on a hairpin course, consistency, verona-like, riders,
bad inputs, caching, and the `plan` / `compare-riders` CLI end to end.

The 3D plan, the mesh study and the 3D three-rider comparison on verona-like are `slow`
(minutes); bench/bench_ocp.py measures them too.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
import yaml
from support.courses import climb_bend_descent, hairpin, straight
from typer.testing import CliRunner, Result

from itt_planner.cli import app
from itt_planner.cli.plan import EXIT_NOT_CONVERGED
from itt_planner.course.geometry import Course, GeoOrigin
from itt_planner.course.loader import load_course
from itt_planner.errors import RiderError, SolveError
from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.dynamics import build_model
from itt_planner.model.rider import PRESETS, Rider
from itt_planner.model.steady import steady_speed_mps
from itt_planner.ocp.analysis import compare_riders, longest_stretch
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.course_settings import OcpSettings, Start
from itt_planner.ocp.guess import plan_guess
from itt_planner.ocp.plan import PLAN_ARRAYS, Plan, corner_table, splits
from itt_planner.ocp.solver import PlanStatus


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


def test_corner_table_and_splits(hairpin_plan: Plan, tmp_path: Path) -> None:
    rows = corner_table(hairpin_plan, hairpin().corners)
    assert len(rows) == 1 and rows[0].braking_s_m is not None
    assert rows[0].apex_speed_mps < rows[0].entry_speed_mps
    sp = splits(hairpin_plan, 200.0)
    assert sp[-1]["elapsed_s"] == pytest.approx(hairpin_plan.finish_time_s)
    assert sum(r["split_s"] for r in sp) == pytest.approx(hairpin_plan.finish_time_s)
    back = Plan.load(hairpin_plan.save(tmp_path / "p.plan.npz"))
    assert back.finish_time_s == pytest.approx(hairpin_plan.finish_time_s)


def test_corner_table_braking_point_is_each_corners_own() -> None:
    """Two corners 150 m apart: the plan brakes for the first only. The second has no
    braking point (it took the first's, 150 m before its apex, as its own)."""
    s = np.arange(0.0, 600.0, 5.0)
    arrays: dict[str, Any] = {name: np.zeros_like(s) for name in PLAN_ARRAYS}
    arrays.update(s_m=s, t_s=s / 12.0, v_mps=np.full_like(s, 12.0),
                  w_n=np.where((s >= 150.0) & (s < 200.0), -0.5, 0.3))
    plan = Plan(model="3d", **arrays, solver_status="synthetic", iterations=0,
                solve_time_s=0.0)
    corners = tuple(SimpleNamespace(apex_s_m=a, entry_s_m=a - 20.0, exit_s_m=a + 20.0,
                                    min_radius_m=30.0) for a in (220.0, 370.0))
    first, second = corner_table(plan, corners)
    assert first.braking_s_m == 150.0 and second.braking_s_m is None


def test_steady_state_matches_power_balance() -> None:
    """Flat straight, CP equal to the whole ride: speed settles at the closed form."""
    rider = PRESETS["paper"]
    p = solve_plan(straight(3000.0), rider, model="1d")
    v_ss = steady_speed_mps(rider.critical_power_w, rider)
    mid = (p.s_m > 1500) & (p.s_m < 2500)
    power = np.mean(p.power_w[mid])
    assert np.mean(p.v_mps[mid]) == pytest.approx(steady_speed_mps(power, rider), rel=0.005)
    assert v_ss > 0


def test_speed_costate_is_the_finish_time_sensitivity() -> None:
    """The plan's speed costate (the horizon's price of terminal speed) is d(finish time)/dv:
    a start 0.2 m/s faster finishes sooner by about costate x 0.2 s (both models)."""
    course, rider = straight(), PRESETS["paper"]
    for model in ("1d", "3d"):
        slow = solve_plan(course, rider, settings=OcpSettings(start_speed_mps=10.0), model=model)
        fast = solve_plan(course, rider, settings=OcpSettings(start_speed_mps=10.2), model=model)
        sensitivity = (fast.finish_time_s - slow.finish_time_s) / 0.2
        assert sensitivity < 0
        assert slow.costate_v_s_per_mps[0] == pytest.approx(sensitivity, rel=0.1)


def test_1d_and_3d_agree_on_a_straight() -> None:
    c = straight()
    t3 = solve_plan(c, PRESETS["paper"], model="3d").finish_time_s
    t1 = solve_plan(c, PRESETS["paper"], model="1d").finish_time_s
    assert t3 == pytest.approx(t1, rel=0.01)


def test_warm_start_from_a_plan(hairpin_plan: Plan) -> None:
    """`guess=`: a plan moved onto another mesh; its own mesh gives back its arrays."""
    course, rider = hairpin(), PRESETS["paper"]
    spm = build_model("3d")
    nodes = hairpin_plan.s_m
    x0, u0 = np.zeros((spm.nx, len(nodes))), np.zeros((spm.nu, len(nodes) - 1))
    x, u = plan_guess(spm, hairpin_plan, nodes, x0, u0)
    assert np.array_equal(x[spm.index("v")], hairpin_plan.v_mps)
    assert np.array_equal(u[0], hairpin_plan.u_delta[:-1])
    # Re-solved from its own solution: the same optimum, sooner (measured 2026-12-01:
    # 22 iterations vs 36 cold, where the cold solve is 26 + 10 after the mesh refinement
    # its verification asked for at the launch, and the warm one starts on the unrefined
    # mesh again; before the verification: 11 vs 103 cold).
    again = solve_plan(course, rider, guess=hairpin_plan)
    assert again.meta["success"], again.solver_status
    assert again.iterations < hairpin_plan.iterations
    assert again.finish_time_s == pytest.approx(hairpin_plan.finish_time_s, rel=1e-5)
    # Onto a uniform 1 m mesh (measured 18 iterations; 40 cold).
    fine = solve_plan(course, rider, settings=OcpSettings(uniform_m=1.0), guess=hairpin_plan)
    assert fine.meta["success"], fine.solver_status
    assert fine.meta["guess"]["n_nodes"] == hairpin_plan.n_nodes
    with pytest.raises(SolveError) as err:  # a plan of another course
        solve_plan(straight(), rider, guess=hairpin_plan)
    assert err.value.status == "invalid_input"


def test_capped_3d_run_resumes_where_it_stopped(hairpin_plan: Plan) -> None:
    """A 3D run stopped by its share of the budget goes on from its last primal-dual
    point (multipliers kept): together no more iterations than one uninterrupted run,
    where a restart from scratch would form the active arcs again."""
    whole = hairpin_plan.meta["attempts"][0]
    assert whole["strategy"] == "cold" and whole["outcome"] == PlanStatus.CONVERGED
    # A budget whose first share (60 %) stops the cold run 1-2 iterations short and
    # leaves more than the 10 iterations a restart needs.
    budget = math.ceil((whole["iterations"] - 1) / 0.6)
    while int(budget * 0.6) >= whole["iterations"]:
        budget -= 1
    assert budget - int(budget * 0.6) > 10, whole
    plan = solve_plan(hairpin(), PRESETS["paper"], settings=OcpSettings(max_iter=budget),
                      model="3d")
    cold, resumed = plan.meta["attempts"][:2]
    assert cold["outcome"] == PlanStatus.CAPPED
    assert resumed["strategy"] == "resume" and resumed["outcome"] == PlanStatus.CONVERGED
    assert cold["iterations"] + resumed["iterations"] <= whole["iterations"] + 5
    assert plan.iterations <= budget


def test_rest_of_the_course_from_a_rider_state(hairpin_plan: Plan) -> None:
    """`start=`: the rest of the course from a mid-course state (the engine's re-plan).
    With a quarter of the plan's W' there, the rest is slower than the plan's rest, W'
    stays >= 0, the start state is kept (a position off the road clipped onto it) and
    the rider still brakes for the hairpin."""
    course, rider, p = hairpin(), PRESETS["paper"], hairpin_plan
    s0 = 150.0
    e0 = 0.25 * float(p.at("e_n", s0))
    state = {"n": 9.0, "alpha": 0.0, "phi": 0.0, "phi_dot": 0.0,
             "v": float(p.at("v_mps", s0)), "w_n": float(p.at("w_n", s0)), "e_n": e0,
             "delta_n": 0.0, "not_a_state": 1.0}
    rest = solve_plan(course, rider, guess=p, start=Start(s_m=s0, state=state))
    assert rest.meta["success"], rest.solver_status
    assert rest.s_m[0] == s0 and rest.s_m[-1] == pytest.approx(course.length_m)
    assert rest.t_s[0] == 0.0
    assert rest.e_n[0] == pytest.approx(e0) and rest.v_mps[0] == pytest.approx(state["v"])
    assert rest.n_m[0] == pytest.approx(4.0 - OcpSettings().margin_m)  # the road's edge
    assert rest.e_n.min() >= -1e-6
    assert rest.finish_time_s > p.finish_time_s - float(p.at("t_s", s0)) + 0.5
    apex = course.corners[0].apex_s_m
    assert rest.w_n[(rest.s_m > apex - 150) & (rest.s_m < apex)].min() < 0
    with pytest.raises(SolveError):  # a guess that starts after the mesh
        solve_plan(course, rider, guess=rest, start=Start(s_m=50.0, state=state))


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
    plan = solve_plan(wall, weak, settings=OcpSettings(max_iter=60, max_cpu_time_s=20.0),
                      model="1d")
    assert plan.status in ("capped", "failed", "invalid") and not plan.meta["success"]


# ---- verona-like: 1D vs 3D, riders ------------------------------------------------------

@pytest.fixture(scope="module")
def verona() -> Course:
    return load_course("verona-like")


@pytest.fixture(scope="module")
def verona_plan_1d(verona: Course) -> Plan:
    """The typical rider on verona-like, 1D (a few seconds)."""
    return solve_plan(verona, PRESETS["typical"], model="1d")


@pytest.fixture(scope="module")
def verona_plans(verona: Course, verona_plan_1d: Plan) -> dict[str, Plan]:
    """The typical rider on verona-like with both models (the 3D solve: 1.5-4 min on 2
    cores, hence only in `slow` tests)."""
    return {"3d": solve_plan(verona, PRESETS["typical"], model="3d"), "1d": verona_plan_1d}


@pytest.mark.slow
def test_verona_1d_is_faster_and_overspeeds_the_hairpins(verona: Course,
                                                         verona_plans: dict[str, Plan]) -> None:
    p3, p1 = verona_plans["3d"], verona_plans["1d"]
    assert p3.meta["success"] and p1.meta["success"], (p3.solver_status, p1.solver_status)
    assert p1.finish_time_s < p3.finish_time_s
    grip = 1.0 * GRAVITY_MPS2  # dry: mu_y = 1
    assert p3.friction_use.max() <= 1 + 1e-3  # C16 everywhere on the 3D plan
    assert np.abs(p3.ay_mps2).max() <= grip * (1 + 1e-3)
    hairpins = [c for c in verona.corners if c.min_radius_m <= 16.0]
    assert len(hairpins) >= 2
    for c in hairpins:
        v1 = float(p1.at("v_mps", c.apex_s_m))
        v3 = float(p3.at("v_mps", c.apex_s_m))
        # The 1D model ignores the bend: its apex speed needs more than the grip on the
        # centre-line radius; the 3D rider is slower there and within the grip (its line
        # is wider than the centre line, so v3^2/R may not bound it).
        assert v1 * v1 / c.min_radius_m > grip, (c.apex_s_m, v1)
        assert v3 < v1


def _section_time(plan: Plan, s0: float, s1: float) -> float:
    return float(plan.at("t_s", s1) - plan.at("t_s", s0))


def test_riders_on_verona_1d(verona: Course, verona_plan_1d: Plan) -> None:
    """Specialist fastest, climber slowest; where the climber loses most (see below).

    model.md section 7 gives the "weak climber" the lowest power-to-mass (4.5 W/kg vs 5.0
    and 5.4) AND the lowest power-to-drag-area of the three, so by the steady power
    balance it loses MORE per km, relatively and absolutely, on the climb than elsewhere:
    the issue's "the climber loses less on the climb" does not follow from these
    parameters (measured: climb x1.131 vs rest x1.107 of the specialist's time; reported
    in bench/RESULTS.md). Asserted instead what the physics says: the relative loss
    on the climb exceeds the loss elsewhere and is at most the steady-state (CP-only)
    ratio, which equal W' narrows.
    """
    plans = {"typical": verona_plan_1d}
    plans |= {r: solve_plan(verona, PRESETS[r], model="1d") for r in ("specialist", "climber")}
    assert all(p.meta["success"] for p in plans.values())
    t = {r: p.finish_time_s for r, p in plans.items()}
    assert t["specialist"] < t["typical"] < t["climber"]
    c0, c1 = longest_stretch(verona, climbing=True)
    assert c1 - c0 > 4000  # the Torricelle climb
    climb = {r: _section_time(p, c0, c1) for r, p in plans.items()}
    loss_climb = climb["climber"] / climb["specialist"]
    loss_rest = (t["climber"] - climb["climber"]) / (t["specialist"] - climb["specialist"])
    grade = math.tan(float(np.mean(verona.beta_rad[(verona.s_m > c0) & (verona.s_m < c1)])))
    v = {r: steady_speed_mps(PRESETS[r].critical_power_w, PRESETS[r], grade=grade)
         for r in ("specialist", "climber")}
    assert 1.0 < loss_rest < loss_climb <= v["specialist"] / v["climber"]


@pytest.mark.slow
def test_riders_on_verona_3d(verona: Course) -> None:
    """`compare_riders` (3 riders x both models): same ordering with the 3D model too."""
    rows = compare_riders(verona)
    assert all(r["status"] == PlanStatus.CONVERGED for r in rows)
    t = {(r["rider"], r["model"]): r["finish_time_s"] for r in rows}
    for m in ("3d", "1d"):
        assert t[("specialist", m)] < t[("typical", m)] < t[("climber", m)]
        assert t[("typical", m)] > 0
    assert all(t[(r, "1d")] < t[(r, "3d")] for r in PRESETS if (r, "3d") in t)


@pytest.mark.slow
def test_non_uniform_mesh_matches_uniform_1m_on_verona(verona: Course,
                                                      verona_plans: dict[str, Plan]) -> None:
    """Mesh bar: the non-uniform mesh's finish time within 0.3 % of a uniform 1 m mesh
    (also measured in bench/bench_ocp.py --mesh-study)."""
    # Cold, the 16,800-node solve stopped unconverged at 400 iterations (bench/RESULTS.md):
    # it starts from the non-uniform plan, with higher caps (measured: 687 iterations,
    # 1324.29 s vs 1325.15 s, +0.065 %; this test ~12 min on 2 cores).
    fine = solve_plan(verona, PRESETS["typical"], settings=OcpSettings(
        uniform_m=1.0, max_iter=1500, max_cpu_time_s=3600.0), guess=verona_plans["3d"])
    assert fine.meta["success"], fine.solver_status
    assert verona_plans["3d"].finish_time_s == pytest.approx(fine.finish_time_s, rel=0.003)


# ---- CLI: plan / compare-riders end to end ------------------------------------------------

# With a 250 m first straight two of the three riders need solve_plan's restart after
# Restoration_Failed (bench/RESULTS.md); 500 m converges at once.
SHORT_COURSE = climb_bend_descent("short", 500.0)
PLAN_KEYS = {"finish_time_s", "mean_power_w", "w_prime_end_j", "max_lean_deg", "solve_time_s",
             "iterations", "n_nodes", "solver_status"}
runner = CliRunner()


def _yaml(path: Path, data: dict[str, Any]) -> Path:
    path.write_text(yaml.safe_dump(data))
    return path


def _no_traceback(result: Result) -> None:
    assert result.exception is None or isinstance(result.exception, SystemExit), result.output
    assert "Traceback" not in result.output


@pytest.mark.parametrize("model", ["3d", "1d"])
def test_plan_cli_json(tmp_path: Path, model: str) -> None:
    course = _yaml(tmp_path / "short.yaml", SHORT_COURSE)
    out = tmp_path / "short.plan.npz"
    result = runner.invoke(app, ["plan", "--course", str(course), "--rider", "typical",
                                 "--model", model, "-o", str(out), "--json"])
    _no_traceback(result)
    assert result.exit_code == 0, result.output
    info = json.loads(result.stdout)
    assert set(info) >= PLAN_KEYS
    assert info["status"] == PlanStatus.CONVERGED and info["success"] is True
    assert 40 < info["finish_time_s"] < 120  # 0.8 km, a sprint on W'
    assert info["n_nodes"] > 50 and info["iterations"] > 0
    assert 0 <= info["w_prime_end_j"] <= 0.02 * PRESETS["typical"].w_prime_j
    assert (info["max_lean_deg"] > 15) if model == "3d" else info["max_lean_deg"] == 0
    assert Plan.load(out).finish_time_s == pytest.approx(info["finish_time_s"], abs=0.01)
    # The plan remembers its course file: `report PLAN` needs no --course.
    report = runner.invoke(app, ["report", str(out), "-o", str(tmp_path / "r.html"), "--json"])
    _no_traceback(report)
    assert report.exit_code == 0, report.output
    assert json.loads(report.stdout)["course"] == "short"


def test_plan_cli_1d_on_the_shortest_line(tmp_path: Path) -> None:
    """`--line shortest`: the 1D rides the shortest line within the road, so it is faster
    than on the centre line; the 3D model refuses the option (it picks its own line)."""
    course = _yaml(tmp_path / "short.yaml", SHORT_COURSE)
    runs = {line: runner.invoke(app, ["plan", "--course", str(course), "--rider", "typical",
                                      "--model", "1d", "--line", line, "--json"])
            for line in ("centre", "shortest")}
    info = {line: json.loads(r.stdout) for line, r in runs.items()}
    assert all(r.exit_code == 0 for r in runs.values()), info
    assert info["shortest"]["line"] == "shortest" and info["shortest"]["verified"] is True
    assert info["shortest"]["finish_time_s"] < info["centre"]["finish_time_s"]
    refused = runner.invoke(app, ["plan", "--course", str(course), "--model", "3d",
                                  "--line", "shortest", "--json"])
    _no_traceback(refused)
    assert refused.exit_code == 1 and "--line" in json.loads(refused.stdout)["error"]


def test_compare_riders_cli_json(tmp_path: Path) -> None:
    course = _yaml(tmp_path / "short.yaml", SHORT_COURSE)
    result = runner.invoke(app, ["compare-riders", "--course", str(course), "--json"])
    _no_traceback(result)
    assert result.exit_code == 0, result.output
    rows = json.loads(result.stdout)["riders"]
    assert {(r["rider"], r["model"]) for r in rows} == {
        (r, m) for r in ("typical", "specialist", "climber") for m in ("3d", "1d")}
    assert all(r["status"] == PlanStatus.CONVERGED for r in rows)
    t = {(r["rider"], r["model"]): r for r in rows}
    # (No rider order here: 0.8 km is a ~50 s sprint decided by W' and mass, not CP.)
    for m in ("3d", "1d"):
        assert 0 < t[("typical", m)]["descent_time_s"] < t[("typical", m)]["finish_time_s"]
        assert 0 < t[("typical", m)]["climb_time_s"] < t[("typical", m)]["finish_time_s"]
    # The 1D model takes the 14 m bend faster than the grip allows.
    assert t[("typical", "1d")]["corner_time_s"] < t[("typical", "3d")]["corner_time_s"]


def test_plan_cli_bad_settings(tmp_path: Path) -> None:
    course = _yaml(tmp_path / "short.yaml", SHORT_COURSE)
    # Zero critical power: a rider error, exit 1, one JSON error object.
    rider = _yaml(tmp_path / "zero.yaml", {"critical_power_w": 0.0})
    result = runner.invoke(app, ["plan", "--course", str(course), "--rider", str(rider),
                                 "--json"])
    _no_traceback(result)
    assert result.exit_code == 1
    err = json.loads(result.stdout)
    assert err["type"] == "RiderError" and "critical_power_w" in err["error"]
    # Road narrower than the bike: the OCP refuses it (SolveError invalid_input).
    narrow = _yaml(tmp_path / "narrow.yaml", {**SHORT_COURSE, "width_left_m": 0.2,
                                              "width_right_m": 0.2})
    result = runner.invoke(app, ["plan", "--course", str(narrow), "--json"])
    _no_traceback(result)
    assert result.exit_code == 1
    err = json.loads(result.stdout)
    assert err["type"] == "SolveError" and "narrower than the bike" in err["error"]
    # A rider too weak for a 30 % wall, default caps: a solver status, exit code 3.
    wall = _yaml(tmp_path / "wall.yaml", {"name": "wall", "segments": [
        {"type": "straight", "length_m": 100.0}, {"type": "straight", "length_m": 300.0,
                                                  "grade_pct": 30.0}]})
    weak = _yaml(tmp_path / "weak.yaml", {"critical_power_w": 60.0, "max_power_w": 200.0,
                                          "w_prime_j": 2000.0})
    result = runner.invoke(app, ["plan", "--course", str(wall), "--rider", str(weak),
                                 "--model", "1d", "--json"])
    _no_traceback(result)
    assert result.exit_code == EXIT_NOT_CONVERGED
    info = json.loads(result.stdout)
    assert info["success"] is False
    assert info["iterations"] <= OcpSettings().budget("1d", 400.0)[0]
    assert info["status"] == "capped" and info["verified"] is not True


def test_plan_cli_allow_unconverged(tmp_path: Path) -> None:
    """An unconverged plan is used only on request, and then says so (JSON and stderr);
    a converged one carries its verification."""
    runner = CliRunner()
    wall = _yaml(tmp_path / "wall.yaml", {"name": "wall", "segments": [
        {"type": "straight", "length_m": 100.0}, {"type": "straight", "length_m": 300.0,
                                                  "grade_pct": 30.0}]})
    weak = _yaml(tmp_path / "weak.yaml", {"critical_power_w": 60.0, "max_power_w": 200.0,
                                          "w_prime_j": 2000.0})
    result = runner.invoke(app, ["plan", "--course", str(wall), "--rider", str(weak),
                                 "--model", "1d", "--max-iter", "50", "--json",
                                 "--allow-unconverged"])
    _no_traceback(result)
    assert result.exit_code == 0
    info = json.loads(result.stdout)
    assert info["allowed_unconverged"] is True and info["success"] is False
    assert info["status"] in ("capped", "failed", "invalid")
    assert "not fit for use" in result.stderr and "--allow-unconverged" in result.stderr
    ok = _yaml(tmp_path / "ok.yaml", SHORT_COURSE)
    result = runner.invoke(app, ["plan", "--course", str(ok), "--model", "1d", "--json"])
    assert result.exit_code == 0, result.stdout
    info = json.loads(result.stdout)
    assert info["status"] == "converged" and info["verified"] is True
    assert "allowed_unconverged" not in info
    assert info["verification"]["max_speed_error_mps"] < 0.3
    assert info["attempts"][0]["strategy"] == "cold"
    # The bend's speed is limited by nothing in the 1D model: said, not left to be read.
    [warning] = info["warnings"]
    assert "1D model has no corners" in warning and "--model 3d" in warning


def test_plan_cli_air_at_the_courses_altitude(tmp_path: Path) -> None:
    """A course at 1,000 m: the plan in the paper's sea-level air says what the course's
    own air is (ISA at 15 C, 1.09 kg/m^3, drag 12 % lower), and plans in it when told;
    thinner air, a faster plan. At sea level (the same course at 0 m) nothing is said."""
    high = _yaml(tmp_path / "high.yaml", {**SHORT_COURSE, "origin": {
        "lat_deg": 45.0, "lon_deg": 11.0, "alt_m": 1000.0}})
    low = _yaml(tmp_path / "low.yaml", {**SHORT_COURSE, "origin": {
        "lat_deg": 45.0, "lon_deg": 11.0, "alt_m": 0.0}})
    sea = json.loads(runner.invoke(app, ["plan", "--course", str(high), "--model", "1d",
                                         "--json"]).stdout)
    air = [w for w in sea["warnings"] if "air" in w]
    assert len(air) == 1 and "--air-density-kgpm3 1.09" in air[0], sea["warnings"]
    thin = json.loads(runner.invoke(app, ["plan", "--course", str(high), "--model", "1d",
                                          "--air-density-kgpm3", "1.09", "--json"]).stdout)
    assert not [w for w in thin["warnings"] if "air" in w]
    assert thin["finish_time_s"] < sea["finish_time_s"]
    at_sea = json.loads(runner.invoke(app, ["plan", "--course", str(low), "--model", "1d",
                                            "--json"]).stdout)
    assert not [w for w in at_sea["warnings"] if "air" in w]
    # The day's temperature instead: ISA pressure at the course's mean altitude.
    mild = json.loads(runner.invoke(app, ["plan", "--course", str(high), "--model", "1d",
                                          "--air-temperature-c", "15", "--json"]).stdout)
    hot = json.loads(runner.invoke(app, ["plan", "--course", str(high), "--model", "1d",
                                         "--air-temperature-c", "35", "--json"]).stdout)
    assert not [w for w in mild["warnings"] + hot["warnings"] if "air" in w]
    assert mild["conditions"]["air_temperature_c"] == 15.0
    assert mild["conditions"]["air_density_kgpm3"] == pytest.approx(1.09, abs=0.005)
    assert hot["conditions"]["air_density_kgpm3"] == pytest.approx(
        1.09 * 288.15 / 308.15, abs=0.005)
    assert mild["finish_time_s"] == pytest.approx(thin["finish_time_s"], rel=1e-3)
    assert hot["finish_time_s"] < mild["finish_time_s"]
    for bad, message in ((["--air-temperature-c", "35", "--air-density-kgpm3", "1.1"],
                          "give one"), (["--air-temperature-c", "80"], "air temperature 80")):
        result = runner.invoke(app, ["plan", "--course", str(high), "--model", "1d", *bad,
                                     "--json"])
        assert result.exit_code == 1 and message in json.loads(result.stdout)["error"]


def test_rider_cornering_limit_lowers_corner_speed() -> None:
    """A rider's own lateral limit (issue 14 item 4) is C16's: corners slower, a_y within
    it everywhere; grip alone corners faster."""
    course = hairpin(straight_m=150.0, radius_m=20.0)
    grip = solve_plan(course, PRESETS["paper"], model="3d")
    timid_rider = Rider(name="timid", max_lateral_accel_mps2=4.0)
    timid = solve_plan(course, timid_rider, model="3d")
    assert grip.converged and timid.converged, (grip.meta["attempts"], timid.meta["attempts"])
    assert np.max(np.abs(timid.ay_mps2)) <= 4.0 * 1.01
    assert np.max(np.abs(grip.ay_mps2)) > 6.0
    apex = course.corners[0].apex_s_m
    assert timid.at("v_mps", apex) < 0.85 * grip.at("v_mps", apex)
    assert timid.finish_time_s > grip.finish_time_s
