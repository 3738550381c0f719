"""Re-solving the rest of the course beside the live loop (`live.course_replan`): the
start taken from the rider's state, a re-solve from mid-course in the worker process
(adopted at its stamp delay), the request rules, and failures reported, never hidden."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from support.courses import hairpin

from itt_planner.errors import SolveError
from itt_planner.live.course_replan import CourseReplanner, CourseReplanSettings, start_from
from itt_planner.live.resolve_model import Warm
from itt_planner.live.resolve_worker import WORKER_PROGRAM
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import PRESETS
from itt_planner.model.state import RiderState
from itt_planner.ocp.cache import with_point
from itt_planner.ocp.course_problem import solve_plan, solve_plan_point
from itt_planner.ocp.course_settings import OcpSettings
from itt_planner.ocp.horizon import HorizonPlanner
from itt_planner.ocp.horizon_settings import HorizonSettings
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import PlanStatus

COURSE = hairpin(straight_m=300.0)
RIDER = PRESETS["paper"]
#: Where the rider left the plan: before the hairpin, 4 kJ of W' short, 10 % slow.
S_OFF_M = 150.0


@pytest.fixture(scope="module")
def plan() -> Plan:
    plan = solve_plan(COURSE, RIDER, model="3d")
    assert plan.converged, plan.meta["attempts"]
    return plan


@pytest.fixture(scope="module")
def planner(plan: Plan) -> HorizonPlanner:
    return HorizonPlanner(COURSE, RIDER, plan, settings=HorizonSettings(horizon_m=300.0))


def off_plan_state(plan: Plan, s_m: float = S_OFF_M) -> RiderState:
    t = float(plan.at("t_s", s_m))
    return RiderState(stamp_s=t, s_m=s_m, n_m=float(plan.at("n_m", s_m)),
                      speed_mps=0.9 * float(plan.at("v_mps", s_m)),
                      heading_rad=float(COURSE.at("theta_rad", s_m) + plan.at("alpha_rad", s_m)),
                      power_w=float(plan.at("power_w", s_m)),
                      w_prime_j=float(plan.at("w_prime_j", s_m)) - 4000.0, elapsed_s=t)


@pytest.fixture
def replanner() -> Iterator[CourseReplanner]:
    rp = CourseReplanner(COURSE, Conditions(), CourseReplanSettings(
        period_s=30.0, delay_s=15.0, min_remaining_m=200.0), deterministic=True)
    yield rp
    rp.close()


def test_start_from_the_riders_state(plan: Plan, planner: HorizonPlanner) -> None:
    state = off_plan_state(plan)
    start = start_from(planner, state, S_OFF_M)
    assert start.s_m == S_OFF_M
    assert set(planner.state_names) <= set(start.state)
    assert start.state["v"] == pytest.approx(state.speed_mps)
    assert start.state["e_n"] == pytest.approx(state.w_prime_j / RIDER.w_prime_j)
    # The estimate has no lean: the plan's, where the rider is.
    assert start.state["phi"] == pytest.approx(float(plan.at("phi_rad", S_OFF_M)))
    assert start.state["phi_dot"] == pytest.approx(float(plan.at("phi_dot_radps", S_OFF_M)))
    # Empty and surging: the power is capped to what can still be ramped down to CP
    # without W' going negative, so the re-solve stays feasible.
    empty = dataclasses.replace(state, w_prime_j=0.0, power_w=900.0)
    capped = start_from(planner, empty, S_OFF_M)
    assert capped.state["e_n"] == 0.0
    assert capped.state["w_n"] * RIDER.max_power_w == pytest.approx(RIDER.critical_power_w)


def test_resolve_from_mid_course(plan: Plan, planner: HorizonPlanner,
                                 replanner: CourseReplanner) -> None:
    """The rest of the course from a rider 4 kJ short and 10 % slow: a converged plan
    that starts where and as the rider is, spends the W' left and is slower than the
    old plan's rest; adopted at the stamp delay, not before."""
    state = off_plan_state(plan)
    start = start_from(planner, state, S_OFF_M)
    asked = state.stamp_s
    assert replanner.request(asked, RIDER, plan, start)
    assert not replanner.request(asked + 40.0, RIDER, plan, start)  # one at a time
    assert replanner.take(asked + 14.9) is None  # deterministic: the delay, not the clock
    rest = replanner.take(asked + 15.0)
    assert rest is not None
    assert rest.status == PlanStatus.CONVERGED, rest.meta["attempts"]
    assert rest.s_m[0] == pytest.approx(S_OFF_M) and rest.s_m[-1] == pytest.approx(
        COURSE.length_m)
    assert rest.v_mps[0] == pytest.approx(state.speed_mps, rel=1e-6)
    assert rest.w_prime_j[0] == pytest.approx(state.w_prime_j, rel=1e-6)
    assert rest.w_prime_j.min() >= -0.01 and rest.w_prime_j[-1] <= 0.02 * RIDER.w_prime_j
    old_rest_s = plan.finish_time_s - float(plan.at("t_s", S_OFF_M))
    assert rest.finish_time_s > old_rest_s  # less W' and less speed: slower
    assert rest.meta["start"]["s_m"] == S_OFF_M
    # The period rate-limits the next request.
    assert not replanner.request(asked + 20.0, RIDER, rest, start)


def test_request_rules(plan: Plan, planner: HorizonPlanner) -> None:
    """No worker is started when re-solving is off or the finish is near."""
    start = start_from(planner, off_plan_state(plan), S_OFF_M)
    off = CourseReplanner(COURSE, Conditions(), CourseReplanSettings(period_s=0.0),
                          deterministic=True)
    near = CourseReplanner(COURSE, Conditions(), CourseReplanSettings(
        min_remaining_m=COURSE.length_m), deterministic=True)
    try:
        assert not off.request(0.0, RIDER, plan, start)
        assert not near.request(0.0, RIDER, plan, start)
        assert off.take(1e9) is None and near.take(1e9) is None
    finally:
        off.close()
        near.close()


def test_unconverged_resolve_is_reported(plan: Plan, planner: HorizonPlanner) -> None:
    """A re-solve that runs out of budget comes back as a plan that says so; the next
    re-solve runs in the same worker process (no new process and imports per re-solve)."""
    rp = CourseReplanner(COURSE, Conditions(), CourseReplanSettings(
        min_remaining_m=200.0, ocp=OcpSettings(max_iter=3)), deterministic=False)
    try:
        start = start_from(planner, off_plan_state(plan), S_OFF_M)
        for stamp in (0.0, 100.0):
            assert rp.request(stamp, RIDER, plan, start)
            rest = _wait(rp)
            assert rest.status != PlanStatus.CONVERGED and not rest.meta["success"]
            assert rest.iterations <= 3
        assert rp.workers_started == 1
    finally:
        rp.close()


def test_failed_solve_and_dead_worker_are_reported(plan: Plan, planner: HorizonPlanner) -> None:
    """A solve that raises in the worker (here: a road narrower than the bike) is raised
    by `take` with its status, for the caller to log, and the worker goes on; a worker
    that dies is a `SolveError` "worker_failed", and the next request starts another."""
    narrow = hairpin(straight_m=300.0, width_m=0.4)
    rp = CourseReplanner(narrow, Conditions(), CourseReplanSettings(min_remaining_m=200.0),
                         deterministic=False)
    start = start_from(planner, off_plan_state(plan), S_OFF_M)
    try:
        assert rp.request(0.0, RIDER, plan, start)
        with pytest.raises(SolveError) as err:
            _wait(rp)
        assert err.value.status == "invalid_input"
        assert "narrower than the bike" in str(err.value)
        worker = rp._worker
        assert worker is not None
        assert worker.poll() is None  # still there for the next re-solve
        worker.kill()
        assert rp.request(100.0, RIDER, plan, start)
        with pytest.raises(SolveError) as err:
            _wait(rp)
        assert err.value.status == "worker_failed"
        assert rp.request(200.0, RIDER, plan, start)
        with pytest.raises(SolveError) as err:
            _wait(rp)
        assert err.value.status == "invalid_input"
        assert rp.workers_started == 2
    finally:
        rp.close()


def test_a_worker_started_as_the_replanner_closes_is_killed(plan: Plan,
                                                             planner: HorizonPlanner) -> None:
    """`close` racing the first re-solve's worker start (helper R, 2026-12-03: `close` saw
    no worker yet, the one started next solved its whole course while the node's exit
    waited): the job's worker is killed at once, a "worker_failed" `SolveError`."""
    rp = CourseReplanner(COURSE, Conditions(), CourseReplanSettings(min_remaining_m=200.0),
                         deterministic=False)
    start = start_from(planner, off_plan_state(plan), S_OFF_M)
    rp.close()  # before the worker exists: it is started by the job below
    job = ("3d", COURSE, RIDER, Conditions(), OcpSettings(), plan, start, Warm(), None,
           ("phi", "delta_n"))
    t0 = time.monotonic()
    with pytest.raises(SolveError) as err:
        rp._solve_in_worker(job)
    assert err.value.status == "worker_failed"
    assert time.monotonic() - t0 < 5.0  # not the solve's seconds
    assert rp.workers_started == 1


def _wait(rp: CourseReplanner, timeout_s: float = 120.0) -> Plan:
    """A live engine's polling: `take` until the worker is done."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        got = rp.take(0.0)
        if got is not None:
            return got
        time.sleep(0.05)
    raise AssertionError("the course re-solve did not finish")


def test_a_resolves_cpu_cap_scales_with_the_rest_of_the_course() -> None:
    """`CourseReplanSettings.ocp_for`: the full-course budget of the model for the rest
    (1D 20 s + 2 s per km, 3D 60 s + 15 s per km) at most `max_cpu_s`; a cap the
    settings give is kept."""
    st = CourseReplanSettings()
    assert st.ocp_for("1d-line", 20_000.0).max_cpu_time_s == pytest.approx(60.0)
    assert st.ocp_for("1d-line", 91_000.0).max_cpu_time_s == pytest.approx(st.max_cpu_s)
    assert st.ocp_for("3d", 2_000.0).max_cpu_time_s == pytest.approx(90.0)
    assert st.ocp_for("3d", 20_000.0).max_cpu_time_s == pytest.approx(st.max_cpu_s)
    fixed = CourseReplanSettings(ocp=OcpSettings(max_cpu_time_s=30.0))
    assert fixed.ocp_for("3d", 20_000.0).max_cpu_time_s == 30.0


def test_a_failed_resolve_leaves_the_next_one_warm(planner: HorizonPlanner) -> None:
    """The plan in force keeps its point for the re-solves after one that failed: the
    next re-solve from it starts from the last 3D plan's point, not cold."""
    plan = with_point(*solve_plan_point(COURSE, RIDER, model="3d"))
    rp = CourseReplanner(COURSE, Conditions(), CourseReplanSettings(
        min_remaining_m=200.0, ocp=OcpSettings(max_iter=3)), deterministic=False, plan=plan)
    try:
        start = start_from(planner, off_plan_state(plan), S_OFF_M)
        for stamp in (0.0, 100.0):
            assert rp.request(stamp, RIDER, plan, start) and rp.last_warm
            assert not _wait(rp).meta["success"]
    finally:
        rp.close()


def test_the_worker_runs_the_owners_code_whatever_its_directory(tmp_path: Path) -> None:
    """`python -c` puts its working directory first on the path: a worker started in
    another checkout imported that checkout's solver. Here the directory holds a package
    of the same name that refuses to import; the worker still starts (and ends with its
    input)."""
    decoy = tmp_path / "itt_planner"
    decoy.mkdir()
    (decoy / "__init__.py").write_text('raise ImportError("the decoy package")\n')
    done = subprocess.run([sys.executable, "-c", WORKER_PROGRAM, str(os.getpid())],
                          cwd=tmp_path, input=b"", capture_output=True, timeout=120,
                          check=False)
    assert done.returncode == 0, done.stderr.decode()
    assert "decoy" not in done.stderr.decode()
