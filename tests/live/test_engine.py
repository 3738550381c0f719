"""PacingEngine: advice contents, stamp clock, fallbacks, diagnostics, determinism,
thread safety, snapshot/restore. Real planner (HorizonPlanner) on the short technical
test course; failures are provoked with real solver budgets, not mocks."""

from __future__ import annotations

import itertools
import json
import math
import threading

import numpy as np
import pytest
from support.hairpin_fixtures import PLAN_CONDITIONS, RIDER

from itt_planner.course.geometry import Course
from itt_planner.live.advice import Advice, Diagnostic, Level
from itt_planner.live.course_replan import CourseReplanSettings
from itt_planner.live.engine import ON_PLAN, EngineSettings, PacingEngine
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed
from itt_planner.ocp.horizon import HorizonPlanner
from itt_planner.ocp.horizon_settings import SUBOPTIMAL_FEASIBLE, HorizonSettings
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import PlanStatus

#: A short horizon keeps the tests fast; a wall-time budget no loaded CI machine hits
#: keeps the solver's path deterministic.
CALM = HorizonSettings(horizon_m=400.0, n_intervals=50, max_wall_time_s=30.0)
#: Engines in tests judge no overruns unless a test is about them (2 busy cores), and
#: replan every period even on the plan: these tests are about the horizon path.
PATIENT = EngineSettings(max_solve_time_s=30.0, on_plan_band_j=0.0)


def _planner(course: Course, plan: Plan, settings: HorizonSettings = CALM) -> HorizonPlanner:
    """A horizon planner believing what the plan was solved for."""
    return HorizonPlanner(course, RIDER, plan, conditions=PLAN_CONDITIONS, settings=settings)


def _ride(engine: PacingEngine, course: Course, plan: Plan, t_end: float, *,
          v_scale: float = 1.0, start: float = 0.0, extra_power_w: float = 0.0) -> list[Advice]:
    """Perfect sensors riding the plan (time-stretched by `v_scale`; the power meter
    reading `extra_power_w` over the plan's), 1 Hz, with an update every second;
    returns the advice."""
    out = []
    for k in range(int(start), int(t_end)):
        t = float(k)
        s = float(np.interp(t * v_scale, plan.t_s, plan.s_m))
        v = float(np.interp(s, plan.s_m, plan.v_mps)) * v_scale
        lat, lon, alt = (float(a) for a in course.to_geodetic(*course.enu_at(s, 0.0)))
        engine.on_sample(GpsFix(t, lat, lon, alt))
        engine.on_sample(WheelSpeed(t, v))
        engine.on_sample(PowerReading(
            t, max(float(np.interp(s, plan.s_m, plan.power_w)), 0.0) + extra_power_w))
        advice = engine.update(t)
        if advice is not None:
            out.append(advice)
    return out


def test_advice_contents(course: Course, plan: Plan) -> None:
    engine = PacingEngine(course, RIDER, plan, settings=PATIENT,
                          planner=_planner(course, plan))
    advice = _ride(engine, course, plan, 15.0)
    assert len(advice) == 15
    solved = [a for a in advice if not a.fallback]
    assert solved, "no replan converged"
    a = solved[-1]
    assert PlanStatus.of(a.solver_status) is PlanStatus.CONVERGED or (
        a.solver_status == SUBOPTIMAL_FEASIBLE)
    assert a.iterations > 0
    assert a.solve_time_s > 0.0
    n = len(a.horizon_s_m)
    for arr in (a.horizon_power_w, a.horizon_speed_mps, a.horizon_n_m, a.line_x_m,
                a.line_y_m, a.line_z_m, a.line_lat_deg, a.line_lon_deg):
        assert arr.shape == (n,) and np.all(np.isfinite(arr))
    assert a.horizon_s_m[0] == pytest.approx(a.state.s_m)
    assert a.horizon_s_m[-1] == pytest.approx(min(a.state.s_m + 400.0, course.length_m), abs=2)
    assert np.all(np.diff(a.horizon_s_m) > 0)
    # The line: ENU from the course at (s, n), and WGS84 that maps back onto it.
    x, y, _ = course.enu_at(a.horizon_s_m, a.horizon_n_m)
    np.testing.assert_allclose(a.line_x_m, x, atol=1e-6)
    # (ENU z is not the ellipsoidal height: passing it back costs millimetres.)
    xb, yb, _ = course.from_geodetic(a.line_lat_deg, a.line_lon_deg, a.line_z_m)
    np.testing.assert_allclose(xb, x, atol=0.05)
    np.testing.assert_allclose(yb, y, atol=0.05)
    # Riding the plan exactly, the replan agrees with the plan.
    assert a.predicted_finish_s == pytest.approx(plan.finish_time_s, rel=0.02)
    assert a.horizon_power_w[1] == pytest.approx(plan.at("power_w", a.horizon_s_m[1]), abs=120.0)
    # The target follows the plan at the rider's power rate (vW_max, 50 W/s), never < 0.
    for before, after in itertools.pairwise(advice):
        assert after.target_power_w >= 0.0
        assert abs(after.target_power_w - before.target_power_w) <= RIDER.power_rate_max_wps * (
            after.stamp_s - before.stamp_s) + 1e-6 or after.cue != before.cue
    assert a.cp_in_use_w == RIDER.critical_power_w and a.plan_version == 0
    assert a.w_prime_now_j == pytest.approx(plan.at("w_prime_j", a.state.s_m), abs=1500.0)
    assert a.w_prime_finish_j == pytest.approx(plan.w_prime_j[-1], abs=3000.0)


def test_on_plan_the_advice_is_the_plan_until_w_prime_leaves_the_band(
        course: Course, plan: Plan,
) -> None:
    """Riding the plan, the advice is the plan itself (no solve); once the W' balance is
    more than the band below the plan's, the horizon replans from the rider's state."""
    engine = PacingEngine(course, RIDER, plan, settings=EngineSettings(max_solve_time_s=30.0),
                          planner=_planner(course, plan))
    advice = _ride(engine, course, plan, 10.0)
    assert all(a.solver_status == ON_PLAN and not a.fallback for a in advice)
    assert engine.counters.get("solves", 0) == 0
    a = advice[-1]
    np.testing.assert_allclose(a.horizon_power_w[1:], plan.at("power_w", a.horizon_s_m[1:]))
    np.testing.assert_allclose(a.horizon_n_m, plan.at("n_m", a.horizon_s_m))
    solver = {d.name: d for d in engine.diagnostics(10.0)}["itt_planner/solver"]
    assert solver.level == Level.OK and "on the plan" in solver.message
    # 600 W over the plan for 10 s: ~6 kJ of W' gone, beyond the 2 kJ band.
    off = _ride(engine, course, plan, 20.0, start=10.0, extra_power_w=600.0)
    assert off[-1].solver_status != ON_PLAN and off[-1].iterations > 0
    assert engine.counters["solves"] >= 1


def test_off_the_plan_the_rest_of_the_course_is_re_solved(course: Course, plan: Plan) -> None:
    """W' out of the band: the horizon replans and the rest of the course is re-solved
    from the rider's state in the background; `delay_s` of stamp time later (the engine
    is deterministic) that plan is the plan in force, advised as such while the rider
    keeps to it."""
    delay = 10.0
    settings = EngineSettings(max_solve_time_s=30.0, deterministic=True,
                              course_replan=CourseReplanSettings(delay_s=delay,
                                                                 min_remaining_m=300.0))
    engine = PacingEngine(course, RIDER, plan, settings=settings, planner=_planner(course, plan))
    try:
        _ride(engine, course, plan, 10.0)
        t = 10
        while (asked := _ride(engine, course, plan, t + 1, start=t,
                              extra_power_w=600.0)[0]).solver_status == ON_PLAN:
            t += 1  # 600 W over the plan until W' leaves the band
        assert engine.counters["course_replans_asked"] == 1
        due = t + int(delay)
        waiting = _ride(engine, course, plan, due, start=t + 1)
        assert engine.plan is plan and all(a.solver_status != ON_PLAN for a in waiting)
        adopted = _ride(engine, course, plan, due + 1, start=due)[0]
        new = engine.plan
        solver = {d.name: d for d in engine.diagnostics(float(due))}["itt_planner/solver"]
        # Still 600 W over: off the new plan at once, so the back-off (`resolve_gate`)
        # doubles the interval to 60 s; then CP is refitted up (the rider holds more
        # than the belief allows), a new belief that resets it: the re-solve for the
        # new CP is asked 30 s after the first, not 60.
        _ride(engine, course, plan, t + 45, start=due + 1, extra_power_w=600.0)
        counters = engine.counters
        held = {d.name: d for d in engine.diagnostics(float(t + 45))}["itt_planner/solver"]
    finally:
        engine.close()
    assert counters["course_replan_backoffs"] == 1
    assert counters["cp_refits"] >= 1
    assert counters["course_replans_asked"] == 2
    assert new is not plan and new.meta["success"]
    assert new.s_m[0] == pytest.approx(asked.state.s_m, abs=0.5)
    assert new.w_prime_j[0] == pytest.approx(asked.state.w_prime_j, abs=50.0)
    assert new.w_prime_j.min() >= -1.0
    # The rider rode the old plan's power meanwhile, within the band of the new one.
    assert adopted.solver_status == ON_PLAN
    np.testing.assert_allclose(adopted.horizon_power_w[1:],
                               new.at("power_w", adopted.horizon_s_m[1:]))
    assert solver.values["course_replans"] == "1"
    # The back-off is on /diagnostics too, not only in the counters.
    assert held.values["course_replan_backoffs"] == "1"


def test_clocked_by_stamps_only(course: Course, plan: Plan) -> None:
    engine = PacingEngine(course, RIDER, plan,
                          settings=EngineSettings(replan_period_s=2.0, max_solve_time_s=30.0,
                                                  on_plan_band_j=0.0),
                          planner=_planner(course, plan))
    assert engine.update(0.0) is None  # no state yet
    engine.on_sample(WheelSpeed(0.0, 5.0))
    assert engine.update(0.0) is None  # speed alone does not place the rider
    lat, lon, alt = (float(a) for a in course.to_geodetic(*course.enu_at(20.0, 0.0)))
    engine.on_sample(GpsFix(0.5, lat, lon, alt))
    first = engine.update(1.0)
    assert first is not None and first.stamp_s == 1.0
    assert engine.update(2.5) is None  # 1.5 s of stamp time: not due
    assert engine.update(3.0) is not None
    # Only the stamps count: a burst of calls at one stamp gives nothing new.
    assert all(engine.update(3.0) is None for _ in range(3))


def test_fallback_keeps_last_good_advice_shifted(course: Course, plan: Plan) -> None:
    good = _planner(course, plan)
    engine = PacingEngine(course, RIDER, plan, settings=PATIENT, planner=good)
    advice = _ride(engine, course, plan, 20.0)
    last_good = [a for a in advice if not a.fallback][-1]
    fallbacks_before = engine.counters.get("fallbacks", 0)
    # The solver now gets no iterations at all: every replan fails for real.
    engine.horizon.planner = _planner(course, plan, HorizonSettings(max_iter=0))
    failed = _ride(engine, course, plan, 25.0, start=20.0)
    assert all(a.fallback for a in failed)
    assert PlanStatus.of(failed[0].solver_status.split("; ")[0]) is PlanStatus.CAPPED
    a = failed[-1]
    assert a.state.s_m > last_good.state.s_m
    # The old solution, cut at the new position (not a new plan).
    mask = last_good.horizon_s_m > a.state.s_m
    np.testing.assert_allclose(a.horizon_s_m[1:], last_good.horizon_s_m[mask])
    np.testing.assert_allclose(a.horizon_power_w[1:], last_good.horizon_power_w[mask])
    diags = {d.name: d for d in engine.diagnostics(24.0)}
    solver = diags["itt_planner/solver"]
    assert solver.level == Level.ERROR  # 5 failures in a row >= 3
    assert int(solver.values["fallbacks"]) == fallbacks_before + 5
    # ... counting a failed replan at the end of the good stretch (a launch at 1,250 W
    # takes this planner 50-60 iterations, at its cap of 60: a capped iterate may fail)
    trailing = len(advice) - 1 - advice.index(last_good)
    assert solver.values["consecutive_failures"] == str(5 + trailing)
    assert "last good advice" in solver.message
    rider_model = diags["itt_planner/rider_model"]  # the rider followed: no CP refit
    assert rider_model.level == Level.OK and rider_model.values["refits"] == "0"
    # Recovery: a working planner again clears the error.
    engine.horizon.planner = good
    back = _ride(engine, course, plan, 30.0, start=25.0)
    assert not all(a.fallback for a in back)
    if not back[-1].fallback:
        assert {d.name: d for d in engine.diagnostics(30.0)}[
            "itt_planner/solver"].level == Level.OK


def test_fallback_before_any_good_solve_uses_the_plan(course: Course, plan: Plan) -> None:
    engine = PacingEngine(course, RIDER, plan, settings=EngineSettings(on_plan_band_j=0.0),
                          planner=_planner(course, plan,
                                           HorizonSettings(horizon_m=400.0, max_iter=0)))
    a = _ride(engine, course, plan, 6.0)[-1]
    assert a.fallback
    np.testing.assert_allclose(a.horizon_speed_mps, plan.at("v_mps", a.horizon_s_m))
    # Over the planner's horizon: its HorizonSettings own the length.
    assert a.horizon_s_m[-1] == pytest.approx(a.state.s_m + 400.0)
    assert a.predicted_finish_s == pytest.approx(plan.finish_time_s, rel=0.02)


def test_overrun_is_a_fallback_unless_deterministic(course: Course, plan: Plan) -> None:
    planner = _planner(course, plan)
    live = PacingEngine(course, RIDER, plan, planner=planner,
                        settings=EngineSettings(max_solve_time_s=0.0, on_plan_band_j=0.0))
    advice = _ride(live, course, plan, 4.0)
    assert all(a.fallback and a.solver_status.startswith("overrun") for a in advice)
    assert live.counters["overruns"] == 4
    replay = PacingEngine(course, RIDER, plan, planner=_planner(course, plan),
                          settings=EngineSettings(max_solve_time_s=0.0, deterministic=True,
                                                  on_plan_band_j=0.0))
    advice = _ride(replay, course, plan, 4.0)
    assert not any(a.fallback for a in advice)
    assert all(a.solve_time_s == 0.0 for a in advice)
    assert "solve_time_s" not in replay.diagnostics(4.0)[0].values


def test_deterministic_replay_is_identical(course: Course, plan: Plan) -> None:
    def run() -> tuple[list[Advice], list[Diagnostic]]:
        engine = PacingEngine(course, RIDER, plan,
                              settings=EngineSettings(deterministic=True,
                                                      max_solve_time_s=0.0,
                                                      on_plan_band_j=0.0),
                              planner=_planner(course, plan))
        advice = _ride(engine, course, plan, 8.0, v_scale=0.97)
        return advice, engine.diagnostics(12.0)

    (a1, d1), (a2, d2) = run(), run()
    assert len(a1) == len(a2) == 8
    for x, y in zip(a1, a2, strict=True):
        for name in ("horizon_s_m", "horizon_power_w", "horizon_n_m", "line_lat_deg"):
            assert np.array_equal(getattr(x, name), getattr(y, name))
        assert (x.target_power_w, x.predicted_finish_s, x.solve_time_s, x.solver_status) == \
               (y.target_power_w, y.predicted_finish_s, y.solve_time_s, y.solver_status)
    assert d1 == d2


def test_bad_inputs_and_staleness_in_diagnostics(course: Course, plan: Plan) -> None:
    engine = PacingEngine(course, RIDER, plan, settings=PATIENT,
                          planner=_planner(course, plan))
    _ride(engine, course, plan, 3.0)
    engine.on_sample(PowerReading(3.0, math.nan))
    engine.on_sample(WheelSpeed(3.0, -1.0))
    engine.on_sample(GpsFix(1.0, 0.0, 0.0, 0.0))  # time going backwards
    engine.on_sample(GpsFix(3.0, 46.0, 11.0, 0.0))  # far off the course
    diags = {d.name: d for d in engine.diagnostics(3.0)}
    rejected = diags["itt_planner/inputs_rejected"]
    assert rejected.level == Level.WARN
    assert rejected.values["power_invalid"] == "1" and rejected.values["speed_invalid"] == "1"
    assert rejected.values["gps_time_backwards"] == "1"
    assert rejected.values["gps_off_course"] == "1"
    assert diags["itt_planner/input/gps"].level == Level.OK
    # Reported once: the next report is OK again; 10 s later every input is stale.
    later = {d.name: d for d in engine.diagnostics(12.0)}
    assert later["itt_planner/inputs_rejected"].level == Level.OK
    assert all(later[f"itt_planner/input/{t}"].level == Level.STALE
               for t in ("gps", "speed", "power"))


def test_inputs_from_other_threads_while_solving(course: Course, plan: Plan) -> None:
    engine = PacingEngine(course, RIDER, plan, settings=PATIENT,
                          planner=_planner(course, plan))
    _ride(engine, course, plan, 2.0)
    errors: list[Exception] = []

    def feed() -> None:
        try:
            for k in range(2000):
                engine.on_sample(PowerReading(2.0 + k * 1e-3, 400.0))
                engine.on_sample(WheelSpeed(2.0 + k * 1e-3, 12.0))
        except Exception as err:  # noqa: BLE001  # pragma: no cover - reported below
            errors.append(err)

    thread = threading.Thread(target=feed)
    thread.start()
    advice = [engine.update(2.0 + k) for k in range(3)]
    thread.join()
    assert not errors and all(a is not None for a in advice)
    assert engine.counters["power_accepted"] == 2 + 2000


def test_snapshot_restore_across_a_restart(course: Course, plan: Plan) -> None:
    planner = _planner(course, plan)
    engine = PacingEngine(course, RIDER, plan, settings=PATIENT, planner=planner)
    _ride(engine, course, plan, 12.0)
    before = engine.state
    assert before is not None
    snap = json.loads(json.dumps(engine.snapshot()))  # what a node writes to disk
    fresh = PacingEngine(course, RIDER, plan, settings=PATIENT, planner=planner)
    fresh.restore(snap)
    after = fresh.state
    assert after is not None
    assert after.w_prime_j == pytest.approx(before.w_prime_j)
    assert after.s_m == pytest.approx(before.s_m)
    assert after.elapsed_s == pytest.approx(before.elapsed_s)
    advice = _ride(fresh, course, plan, 14.0, start=12.0)
    assert advice and advice[0].state.s_m >= before.s_m
