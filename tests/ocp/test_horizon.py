"""Receding-horizon OCP: replans along hairpins, usable-rate on a technical descent, W' >= 0,
warm starts, budget-capped iterates that are still valid advice, the rescue, failures."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
import pytest
from support.courses import hairpin, switchback_climb

from itt_planner.course.builder import build_course
from itt_planner.course.geometry import Course
from itt_planner.course.loader import load_course
from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.dynamics import build_3d_steady_lean
from itt_planner.model.rider import PRESETS, Rider
from itt_planner.model.state import RiderState
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.horizon import HorizonPlanner
from itt_planner.ocp.horizon_settings import SMOOTHED_FEASIBLE, HorizonSettings, HorizonSolution
from itt_planner.ocp.horizon_window import HorizonWindow
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import PlanStatus, SolveResult

COURSE = hairpin(straight_m=600.0)


@pytest.fixture(scope="module")
def plan() -> Plan:
    return solve_plan(COURSE, PRESETS["paper"], model="3d")


@pytest.fixture(scope="module")
def planner(plan: Plan) -> HorizonPlanner:
    # A generous wall-time cap: on a loaded CI machine outcomes must depend on iterations
    # only. Cold starts on this short hairpin need 50-90 iterations (more than the default
    # cap, which the descent test below exercises): these tests are about warm vs cold.
    return HorizonPlanner(COURSE, PRESETS["paper"], plan,
                          settings=HorizonSettings(horizon_m=500.0, max_iter=150,
                                                   max_wall_time_s=20.0))


def plan_state(plan: Plan, s: float, course: Course = COURSE) -> RiderState:
    return RiderState(
        stamp_s=float(plan.at("t_s", s)), s_m=s, n_m=float(plan.at("n_m", s)),
        speed_mps=float(plan.at("v_mps", s)),
        heading_rad=float(course.at("theta_rad", s) + plan.at("alpha_rad", s)),
        power_w=float(plan.at("power_w", s)), w_prime_j=float(plan.at("w_prime_j", s)),
        elapsed_s=float(plan.at("t_s", s)))


def test_replans_along_a_hairpin(plan: Plan, planner: HorizonPlanner) -> None:
    planner.reset()
    sols = [planner.solve(plan_state(plan, s)) for s in np.arange(0.0, COURSE.length_m - 20, 60.0)]
    assert sum(s.success for s in sols) >= len(sols) - 1, [s.status for s in sols]
    for sol in sols:
        assert isinstance(sol, HorizonSolution)
        if sol.success:
            assert sol.w_prime_j.min() >= -0.01
            assert np.all(np.diff(sol.t_s) > 0)
            # Riding the plan's own states predicts the plan's finish.
            assert sol.predicted_finish_s == pytest.approx(plan.finish_time_s, rel=0.02)


def test_horizon_keeps_the_plans_speed_at_its_end(plan: Plan, planner: HorizonPlanner) -> None:
    """The speed carried over the window's end is priced with the plan's costate, so the
    horizon does not ease off towards its end to sell that speed (it did with a quadratic
    pull alone: 0.45 m/s under the plan at the end, power 8-12 W over it in front)."""
    planner.reset()
    sol = planner.solve(plan_state(plan, 50.0))
    assert sol.success, sol.status
    assert sol.v_mps[-1] == pytest.approx(float(plan.at("v_mps", sol.s_m[-1])), abs=0.1)
    last = sol.s_m >= sol.s_m[0] + 0.75 * (sol.s_m[-1] - sol.s_m[0])
    assert np.mean(sol.power_w[last]) == pytest.approx(
        np.mean(plan.at("power_w", sol.s_m[last])), rel=0.05)


def verona_descent() -> Course:
    """The technical descent of verona-like, 8.7-11.2 km: 8 turns, 4 hairpins of 10-15 m."""
    c = load_course("verona-like")
    i, j = int(8700 / c.ds_m), int(11200 / c.ds_m)
    return Course.from_centerline(
        "verona-like-descent", c.x_m[i:j], c.y_m[i:j], c.z_m[i:j], origin=c.origin,
        width_left_m=c.width_left_m[i:j], width_right_m=c.width_right_m[i:j],
        theta_rad=c.theta_rad[i:j], kappa_per_m=c.kappa_per_m[i:j], synthetic=True)


def friction_use(sol: HorizonSolution, rider: Rider) -> np.ndarray:
    """C16 recomputed from the reported profiles: a_x = P / (m v), |a_y| = g tan|phi|."""
    g, mu = GRAVITY_MPS2, 1.0  # Conditions() default grip: mu_x = mu_y = 1
    a_x = sol.power_w / (rider.mass_kg * sol.v_mps)
    a_y = g * np.tan(np.abs(sol.phi_rad))
    use: np.ndarray = (a_x / (mu * g)) ** 2 + (a_y / (mu * g)) ** 2
    return use


def test_usable_replans_on_a_technical_descent() -> None:
    """A realistic sweep: a 1 km replan every 50 m from perturbed plan states down hairpins.

    With the default iteration budget (and a generous wall time, so that the outcome does
    not depend on the machine's load) at least 95 % of the replans are usable, and every
    one returned as success - budget-capped iterates included - respects the road (C11),
    W' >= 0 (C12) and grip (C16 <= 1 + tol beyond what the measured start already uses).
    Converged ones included: with 150 iterations per attempt one replan converged on the
    soft constraints' slacks at a grip use of 1.81 from a start at 1.19 (`BEYOND_LIMITS`).
    """
    course, rider = verona_descent(), PRESETS["typical"]
    plan = solve_plan(course, rider, model="3d")
    settings = HorizonSettings(max_wall_time_s=20.0)
    planner = HorizonPlanner(course, rider, plan, settings=settings)
    rng = np.random.default_rng(0)
    sols, st_of = [], {}
    for s in np.arange(0.0, course.length_m - 20, 50.0):
        st = plan_state(plan, s, course)
        st = dataclasses.replace(
            st, speed_mps=st.speed_mps * (1 + 0.03 * rng.standard_normal()),
            n_m=st.n_m + 0.3 * rng.standard_normal(),
            w_prime_j=max(0.0, st.w_prime_j - rng.uniform(0.0, 1500.0)))
        sols.append(planner.solve(st))
        st_of[id(sols[-1])] = st
    assert sum(sol.success for sol in sols) >= 0.95 * len(sols), [sol.status for sol in sols]
    for sol in (sol for sol in sols if sol.success):
        assert sol.w_prime_j.min() >= -0.01  # C12
        assert np.all(np.diff(sol.t_s) > 0)
        # C11 with the margin, from the second node on (the first is the measured line).
        assert np.all(sol.n_m[1:] <= course.at("width_left_m", sol.s_m[1:]) - 0.5 + 1e-3)
        assert np.all(-sol.n_m[1:] <= course.at("width_right_m", sol.s_m[1:]) - 0.5 + 1e-3)
        # Where the plan corners at the grip limit, no faster than the plan (+ tolerance)
        # unless the rider arrived too fast to brake to it.
        w_n0 = planner.initial_state(st_of[id(sol)], float(sol.s_m[0]))[
            planner.state_names.index("w_n")]
        cap = planner.corner_speed_cap(sol.s_m, float(sol.v_mps[0]), float(w_n0))
        assert np.all(sol.v_mps <= cap + 1e-3)
        use = friction_use(sol, rider)
        assert use[1:].max() <= max(1.0, use[0]) + settings.grip_tol + 1e-3, sol.status


@pytest.mark.parametrize("speed_share", [1.0, 0.6])
def test_usable_replans_up_switchbacks_at_a_crawl(speed_share: float) -> None:
    """A slow rider (90 kg, CdA 0.45, CP 110 W: the plan climbs at 2-3.7 m/s) replanned
    every 25 m up six 15 m switchbacks, perturbed as on the descent above, at the plan's
    speed and at 60 % of it: every replan usable, within grip and the road. With the
    settings before 2026-12-05 (`max_iter` 60, `stiff_ratio` 2.0) 21 of 45 were at the
    plan's speed (the rest refused as `Unresolved_Dynamics`: 20-30 m intervals at 2 m/s)
    and 44 at 60 % (a Suunto watch's switchback circuit: 4.1 % fallbacks, now 0.5 %)."""
    course = build_course(switchback_climb())
    rider = Rider(name="slow", mass_kg=90.0, drag_area_m2=0.45, crr=0.012,
                  critical_power_w=110.0, w_prime_j=12000.0, max_power_w=600.0,
                  max_lateral_accel_mps2=4.0)
    plan = solve_plan(course, rider, model="3d")
    settings = HorizonSettings(max_wall_time_s=20.0)
    planner = HorizonPlanner(course, rider, plan, settings=settings)
    rng = np.random.default_rng(0)
    sols = []
    for s in np.arange(0.0, course.length_m - 50.0, 25.0):
        st = plan_state(plan, s, course)
        sols.append(planner.solve(dataclasses.replace(
            st, speed_mps=st.speed_mps * speed_share, n_m=st.n_m + 0.3 * rng.standard_normal(),
            w_prime_j=max(0.0, st.w_prime_j - rng.uniform(0.0, 1500.0)))))
    assert all(sol.success for sol in sols), [sol.status for sol in sols if not sol.success]
    for sol in sols:
        assert sol.w_prime_j.min() >= -0.01  # C12
        assert np.all(np.abs(sol.n_m[1:]) <= 2.5 - settings.margin_m + 1e-3)  # C11
        use = friction_use(sol, rider)
        assert use[1:].max() <= max(1.0, use[0]) + settings.grip_tol + 1e-3, sol.status


def test_corner_cap_leaves_time_to_build_up_braking(plan: Plan,
                                                    planner: HorizonPlanner) -> None:
    """A rider measured too fast before a grip-limited corner: the cap never asks for more
    speed loss than braking at `corner_cap_brake_g` after the command ramped to it from
    the measured `w_n` at the E6 rate (drag ignored) gives; braking already, as before."""
    rider, st = PRESETS["paper"], planner.settings
    use = plan.at("friction_use", plan.s_m)
    s_corner = float(plan.s_m[np.argmax(use >= st.corner_cap_use)])
    nodes = np.linspace(s_corner - 1.0, s_corner + 19.0, 41)  # the corner 1 m ahead
    v0 = float(plan.at("v_mps", nodes[0])) + 3.0
    rate = 50.0 * rider.power_rate_max_wps / rider.max_power_w  # U_W_MAX, E6
    a_max = st.corner_cap_brake_g * GRAVITY_MPS2
    for w_n0 in (0.0, 0.5):
        # the fastest speed loss: w_n ramps down at `rate`, braking up to a_max
        s, v, t, reach = nodes[0], v0, 0.0, []
        for target in nodes:
            while s < target - 1e-9:
                ds = min(0.05, target - s)
                a = min(max(-(w_n0 - rate * t), 0.0) * Conditions().mu_x * GRAVITY_MPS2,
                        a_max)
                t += ds / v
                v = float(np.sqrt(max(v * v - 2 * a * ds, 1e-6)))
                s += ds
            reach.append(v)
        cap = planner.corner_speed_cap(nodes, v0, w_n0)
        assert np.all(cap >= np.array(reach) - 1e-6)
        # without the ramp (the old cap) the first metres asked for the impossible
        assert np.any(planner.corner_speed_cap(nodes, v0) < np.array(reach) - 0.05)
    np.testing.assert_allclose(planner.corner_speed_cap(nodes, v0, -1.0),
                               planner.corner_speed_cap(nodes, v0))


def test_capped_iterate_returned_only_when_feasible(plan: Plan) -> None:
    """A budget that stops IPOPT early: the iterate is advice only if it is feasible.

    Without the rescue (its own test below), so that a capped attempt is the last one."""
    rider = PRESETS["paper"]
    results = []
    for max_iter in (5, 15, 30):
        short = HorizonPlanner(COURSE, rider, plan,
                               settings=HorizonSettings(horizon_m=500.0, max_iter=max_iter,
                                                        max_wall_time_s=20.0,
                                                        rescue_sharpness_w=0.0))
        for s in (100.0, 300.0, 560.0):
            short.reset()
            results.append((max_iter, short.solve(plan_state(plan, s))))
    outcomes = [(sol.outcome, sol.success) for _, sol in results]
    assert (PlanStatus.CAPPED, True) in outcomes, outcomes
    for max_iter, sol in results:
        if sol.outcome is PlanStatus.CAPPED and sol.success:
            assert sol.iterations == max_iter  # one cold attempt, stopped by the cap
            assert sol.w_prime_j.min() >= 0.0
            assert np.all(np.abs(sol.n_m[1:]) <= 4.0 - 0.5 + 1e-3)
            use = friction_use(sol, rider)
            assert use[1:].max() <= max(1.0, use[0]) + HorizonSettings().grip_tol + 1e-3
        else:
            # Nothing fails here but by the cap: converged, or capped and not feasible.
            assert sol.outcome in (PlanStatus.CONVERGED, PlanStatus.CAPPED), sol.status
            assert sol.success is (sol.outcome is PlanStatus.CONVERGED)


def test_warm_start_from_previous_solution(plan: Plan, planner: HorizonPlanner) -> None:
    """Re-solving the same window from the previous solution is (nearly) free."""
    planner.reset()
    cold = planner.solve(plan_state(plan, 100.0))
    warm = planner.solve(plan_state(plan, 100.0))
    assert cold.success and warm.success
    assert warm.iterations < cold.iterations


def test_warm_start_beats_cold_on_shifted_windows(plan: Plan, planner: HorizonPlanner) -> None:
    """A sequence of windows shifted by ~one replan period: warm needs fewer iterations."""
    positions = np.arange(100.0, 500.0, 20.0)
    planner.reset()
    warm = [planner.solve(plan_state(plan, s)) for s in positions]
    cold = []
    for s in positions:
        planner.reset()
        cold.append(planner.solve(plan_state(plan, s)))
    assert all(w.success for w in warm), [w.status for w in warm]
    assert sum(w.iterations for w in warm[1:]) < sum(c.iterations for c in cold[1:])


def test_off_plan_state_keeps_w_prime_non_negative(plan: Plan) -> None:
    # A cold start with W' nearly empty while surging needs ~120-140 iterations
    # (bench/RESULTS.md): this test gives it the iterations, not the default cap.
    deep = HorizonPlanner(COURSE, PRESETS["paper"], plan,
                          settings=HorizonSettings(horizon_m=500.0, max_iter=300,
                                                   max_wall_time_s=20.0))
    low = dataclasses.replace(plan_state(plan, 200.0), w_prime_j=300.0, power_w=900.0)
    sol = deep.solve(low)
    assert sol.success, sol.status
    assert sol.w_prime_j.min() >= -0.01


@pytest.mark.parametrize("polish_fails", [False, True])
def test_rescue_when_the_exact_nlp_fails(plan: Plan, polish_fails: bool,
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """Both exact attempts failing (as at the E9 kink on a real ride): the continuation
    NLP (E9 switch smoothed over 20 W) is solved and polished in the exact NLP; when the
    polish fails too, the smooth solution is advised with W' recomputed by the exact E9:
    the same line and speeds, W' never below the smooth model's, and valid advice, usable
    but not counted as converged."""
    rider = PRESETS["paper"]
    settings = HorizonSettings(horizon_m=500.0, max_iter=150, max_wall_time_s=20.0)
    rescuer = HorizonPlanner(COURSE, rider, plan, settings=settings)

    def fail(w0: np.ndarray, *_args: object, **_kwargs: object) -> SolveResult:
        return SolveResult(w0, None, None, float("nan"), PlanStatus.FAILED,
                           "Restoration_Failed", 1, 0.0)

    smooth: list[np.ndarray] = []

    def recorded(real: Callable[..., SolveResult]) -> Callable[..., SolveResult]:
        def smooth_solve(*args: object, **kwargs: object) -> SolveResult:
            out = real(*args, **kwargs)
            smooth.append(out.w)
            return out
        return smooth_solve

    for substeps in {settings.substeps, settings.stiff_substeps}:  # whichever a window takes
        nlp = rescuer._nlp(substeps)
        rescue = nlp.rescue
        assert rescue is not None
        for solver in nlp.solvers.values():
            monkeypatch.setattr(solver, "solve", fail)
        if polish_fails:
            monkeypatch.setattr(rescue.polish, "solve", fail)
        monkeypatch.setattr(rescue.smooth, "solve", recorded(rescue.smooth.solve))
    for s in (100.0, 300.0):
        smooth.clear()
        sol = rescuer.solve(plan_state(plan, s))
        assert sol.success, sol.status
        assert (sol.status == SMOOTHED_FEASIBLE) == polish_fails, sol.status
        if polish_fails:
            assert sol.outcome is not PlanStatus.CONVERGED
        assert sol.w_prime_j.min() >= 0.0
        assert np.all(np.abs(sol.n_m[1:]) <= 4.0 - 0.5 + 1e-3)
        use = friction_use(sol, rider)
        assert use[1:].max() <= max(1.0, use[0]) + settings.grip_tol + 1e-3
        if polish_fails:
            x, _, _ = rescuer._tr.layout.split(smooth[-1])
            m = rescuer._model
            np.testing.assert_allclose(sol.v_mps, x[m.index("v")])
            smooth_w_prime = x[m.index("e_n")] * rider.w_prime_j
            # (up to the smooth NLP's own continuity gaps, within its tolerance)
            tol_j = settings.feasible_tol * rider.w_prime_j
            assert np.all(sol.w_prime_j >= smooth_w_prime - tol_j)
            assert sol.w_prime_j[-1] > smooth_w_prime[-1]  # the smooth E9 drains faster


def test_window_capped_by_the_plans_riding_time(plan: Plan) -> None:
    """A window ends where the plan has ridden `max_window_s` (a slow climb), never closer
    than `min_window_m`; 0 s keeps the full `horizon_m`."""
    s0, model, rider = 100.0, build_3d_steady_lean(), PRESETS["paper"]

    def window(**kwargs: float) -> np.ndarray:
        settings = HorizonSettings(horizon_m=500.0, **kwargs)  # type: ignore[arg-type]
        nodes = HorizonWindow(model, COURSE, rider, plan, Conditions(), settings).nodes(s0)
        assert len(nodes) == settings.n_intervals + 1
        assert np.all(np.diff(nodes) > 0)
        return nodes

    assert window(max_window_s=0.0)[-1] == pytest.approx(s0 + 500.0)
    t0 = float(plan.at("t_s", s0))
    for max_window_s, min_window_m in ((10.0, 50.0), (10.0, 300.0)):
        end = max(float(np.interp(t0 + max_window_s, plan.t_s, plan.s_m)), s0 + min_window_m)
        assert end < s0 + 500.0
        nodes = window(max_window_s=max_window_s, min_window_m=min_window_m)
        assert nodes[-1] == pytest.approx(end)


def test_window_capped_by_the_bends_its_nodes_can_follow(plan: Plan) -> None:
    """A window ends where the mesh would ask for `max_density_ratio` times its nodes (a
    run of switchbacks), never closer than `min_window_m`; 0 keeps the full `horizon_m`."""
    s0, model, rider = 450.0, build_3d_steady_lean(), PRESETS["paper"]

    def window(**kwargs: float) -> tuple[HorizonWindow, np.ndarray]:
        settings = HorizonSettings(horizon_m=500.0, max_window_s=0.0,
                                   **kwargs)  # type: ignore[arg-type]
        win = HorizonWindow(model, COURSE, rider, plan, Conditions(), settings)
        nodes = win.nodes(s0)
        assert len(nodes) == settings.n_intervals + 1 and np.all(np.diff(nodes) > 0)
        return win, nodes

    win, nodes = window(max_density_ratio=0.0)
    assert nodes[-1] == pytest.approx(s0 + 500.0)
    asked = float(win._asked(s0, s0 + 500.0)[1][-1])
    n = win.settings.n_intervals
    win, nodes = window(max_density_ratio=0.9 * asked / n)
    assert nodes[-1] < s0 + 500.0
    to_end = float(win._asked(s0, float(nodes[-1]))[1][-1])
    assert to_end == pytest.approx(0.9 * asked, rel=0.01)
    assert window(max_density_ratio=0.01, min_window_m=120.0)[1][-1] == pytest.approx(s0 + 120.0)


def test_failure_returns_status_not_exception(plan: Plan) -> None:
    tight = HorizonPlanner(COURSE, PRESETS["paper"], plan,
                           settings=HorizonSettings(horizon_m=500.0, max_iter=1))
    bad = dataclasses.replace(plan_state(plan, 550.0), speed_mps=25.0, n_m=-3.0, power_w=1800.0)
    sol = tight.solve(bad)
    assert not sol.success
    assert sol.status
    garbage = dataclasses.replace(plan_state(plan, 10.0), speed_mps=float("nan"),
                                  power_w=float("nan"))
    assert isinstance(tight.solve(garbage), HorizonSolution)


def test_horizon_respects_the_riders_cornering_limit() -> None:
    """The rider's lateral limit (issue 14 item 4) holds in the horizon as in the plan."""
    timid = Rider(name="timid", max_lateral_accel_mps2=4.0)
    # The 1D plan (corner speeds capped by the same limit) is the reference, as with
    # `--model 1d`: the limit must hold because the horizon enforces it.
    plan = solve_plan(COURSE, timid, model="1d")
    assert plan.converged, plan.status
    # A cold first replan, generous budget: the outcome must not depend on the load.
    planner = HorizonPlanner(COURSE, timid, plan,
                             settings=HorizonSettings(max_iter=150, max_wall_time_s=20.0))
    apex = COURSE.corners[0].apex_s_m
    sol = planner.solve(plan_state(plan, max(apex - 150.0, 0.0), COURSE))
    assert sol.success, sol.status
    a_y = GRAVITY_MPS2 * np.tan(np.abs(sol.phi_rad[1:]))
    assert a_y.max() <= 4.0 + 0.05 * 9.81  # the soft C16's grip_tol
