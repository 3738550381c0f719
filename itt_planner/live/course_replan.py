"""Re-solving the rest of the course from the rider's state, beside the live loop.

When the rider has left the plan (W' far off the plan's after a hot start, or a CP
refit after the rider ran dry), the receding horizon replans every second, but with
its reduced steady-lean model over 1 km. Following such advice for the rest of a race
cost more than the pacing it corrected: after a CP refit the horizon-led ride on
verona-like lost 1.5-3.4 s per km on the technical descent against the old plan
followed blindly, 15-16 s in all (bench/RESULTS.md). So the engine also asks for a new
plan: the full-course OCP (`ocp.solve_plan`: roll dynamics, the whole remaining course)
from the rider's state, with the W' the rider has and the CP in use. Once adopted it is
THE plan: the advice while the rider keeps to it, the horizon's terminal treatment
otherwise.

The solve takes seconds (the rest of verona-like: 8-31 s measured), so
`CourseReplanner` runs it in a worker process while the inputs and the horizon replans
go on (why a process, not a thread: `CourseReplanner._solve_in_worker`). A live engine takes the
result at its first update after the solve is done. When it is taken up must not depend
on the wall clock in a deterministic replay, nor in a simulation that runs many times
faster than real time: a deterministic engine adopts it `delay_s` of STAMP time after
the request (about a live solve's time), waiting for the worker then if it is late.

Each re-solve starts warm from the primal-dual point of the plan it leaves when that
point is known (`solve_plan(warm=)`): the point a re-solve returned with its plan, or
for the first plan in force the point it was saved or cached with (`plan_point`).
A 3D re-solve from a 1D plan on the line (`RESOLVE_AUTO` near the finish) starts
from the point of the last 3D plan instead (`resolve_model.Warm`, why there). Without
one (an older plan file, a 1D plan) the re-solve starts from the plan's primal point
alone; which way each one started is counted (`last_warm`).

What a re-solve solves (`CourseReplanSettings.model`, `resolve_model`): the 3D OCP of the
rest of the road, or with `RESOLVE_1D_LINE` the 1D OCP on the line of the last plan in
force that was not itself such a re-solve, where no corner ahead needs the 3D. The line
travels with each job as its offset on the road's grid; the worker builds its course
once (`resolve_model.LineCache`).
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.errors import SolveError
from itt_planner.live.resolve_model import (
    RESOLVE_3D,
    RESOLVE_AUTO,
    RESOLVE_MODELS,
    Warm,
    chosen_model,
    on_line,
)
from itt_planner.live.resolve_worker import WORKER_PROGRAM, receive, send
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import Rider
from itt_planner.model.state import RiderState
from itt_planner.ocp.course_nlp import PrimalDual, course_layout, start_speed
from itt_planner.ocp.course_settings import OcpSettings, Start
from itt_planner.ocp.horizon_settings import HorizonSettings
from itt_planner.ocp.plan import Plan

if TYPE_CHECKING:
    from itt_planner.ocp.horizon import HorizonPlanner


@dataclass(frozen=True)
class CourseReplanSettings:
    """When the engine re-solves the rest of the course.

    Attributes:
        period_s: stamp time between two requests at least (0 disables re-solving).
        delay_s: stamp time from a request to adopting its result in a deterministic
            engine (module docstring): about what a solve takes live (the rest of
            verona-like: 8-14 s measured from 2 km on, 31 s from the start).
        min_remaining_m: closer to the finish than this the horizon covers the rest:
            the horizon's length (`HorizonSettings.horizon_m`, its default here;
            `session.config.build_engine` passes the session's).
        ocp: settings of the solve (the full-course plan's); its CPU cap, if it sets
            none, is `ocp_for`'s.
        max_cpu_s: the most CPU seconds a re-solve may take (`ocp_for`).
        backoff_within_s: a rider off a re-solved plan less than this after its
            adoption is not following the plans: the least interval between requests
            doubles (`resolve_gate`); a rider who keeps to one this long resets it.
        backoff_max_s: the longest interval the back-off reaches.
        model: what a re-solve solves: `RESOLVE_3D` (the 3D OCP of the rest of the
            road), `RESOLVE_1D_LINE` (the 1D OCP that knows the corners on the line of
            the last 3D plan in force, the 3D if its plan is refused) or `RESOLVE_AUTO`
            (the 3D within `auto_3d_max_m` of the finish, the 1D on the line before
            and where the 3D fails: `resolve_model`).
        auto_3d_max_m: under `RESOLVE_AUTO`, a rest of the course at most this long is
            re-solved in 3D (its CPU grows with the rest).
    """

    period_s: float = 30.0
    delay_s: float = 15.0
    min_remaining_m: float = HorizonSettings.horizon_m
    ocp: OcpSettings = field(default_factory=OcpSettings)
    max_cpu_s: float = 120.0
    # A period: the Bologna rider left each new plan 0-15 s after its adoption (15 s
    # after the request); 8 periods: a rider who keeps to none is re-solved every 4 min.
    backoff_within_s: float = 30.0
    backoff_max_s: float = 240.0
    model: str = RESOLVE_AUTO
    auto_3d_max_m: float = 20_000.0

    def __post_init__(self) -> None:
        if self.model not in RESOLVE_MODELS:
            msg = f"course re-solve model {self.model!r}: choose one of {RESOLVE_MODELS}"
            raise ValueError(msg)

    def ocp_for(self, model: str, rest_m: float) -> OcpSettings:
        """The settings of a re-solve of `rest_m` of course with `model` (`resolve_model`):
        `ocp`, with the CPU budget a full-course solve of that model and length gets
        (`OcpSettings.budget`: 1D 20 s + 2 s per km, 3D 60 s + 15 s per km), at most
        `max_cpu_s`, unless `ocp` sets its own.

        Why scaled: a fixed 60 s was marginal for the first re-solve on the line of a
        long course, which has no point of its own model to start from: Sauerland's
        from 8.0 km (91 km of 1D on the line, cold from the 3D plan) took 126 iterations,
        41-59 s CPU, and at load ~4 stopped at 60 s after 146 (bench/RESULTS.md,
        2026-12-03, lead, third session). 120 s at most: a plan that comes two minutes
        late is still the plan of the rest, while the horizon paces the rider meanwhile.
        """
        if self.ocp.max_cpu_time_s is not None:
            return self.ocp
        seconds = self.ocp.budget("3d" if model == RESOLVE_3D else "1d", rest_m)[1]
        return replace(self.ocp, max_cpu_time_s=min(seconds, self.max_cpu_s))


#: States of a re-solve's start the rider's estimate does not measure and the solver
#: chooses (`solve_plan(free_start=)`): the lean and the steering; the plan's values
#: where the rider is are only their guess. Fixed at the plan's, a re-solve started from
#: a roll state that belongs to the plan's speed, not the rider's: on the Zwift Bologna
#: ride (bench/RESULTS.md, 2026-12-01, issue 14) the plan rides its corners on the inside
#: edge of the road (C11 active), and a rider 0.9 m/s slower than the plan there, leaning
#: 0.119 rad where the plan's steering at the rider's speed balances 0.102, could only
#: catch the lean by steering further in, off the road: Infeasible_Problem_Detected after
#: 119 iterations; free, converged in 116. (Fixed at the steady turn of the rider's
#: speed it converged in 43, but at a chicane, 5.3 km, where the plan's lean lags its
#: steering, that lean points the other way: no fixed lean fits.) The roll rate keeps
#: the plan's: free too, the solver picked roll states no rider is in (a slow rider in
#: the hairpin leaning 1.2 rad out of the turn, rolling back at 3.6 rad/s; from the
#: plan's own state a rest "faster" than the plan by up to 0.5 s of 11.3 s), 2026-12-02.
UNMEASURED_STATES = ("phi", "delta_n")


def free_states(start: Start, launch_mps: float) -> tuple[str, ...]:
    """The states a re-solve from `start` leaves to the solver: `UNMEASURED_STATES`, or
    for a standing start (`start_from`: the launch speed, no faster) only the steering: a
    stopped rider is upright and still, on a foot. (Free, the solver started a rider
    stopped at the apex of a hairpin at 1 m/s leaning 0.29 rad: verified, but no stopped
    rider is in that state.)"""
    return ("delta_n",) if start.state.get("v", 0.0) <= launch_mps else UNMEASURED_STATES


def start_from(planner: HorizonPlanner, state: RiderState, s_m: float,
               settings: OcpSettings | None = None) -> Start:
    """The OCP start at `s_m`: the horizon model's initial state from `state` (clipped so
    the NLP is feasible: `HorizonPlanner.initial_state`) and the lean of the planner's
    plan there (the estimate has none; the rider is near the plan's line). The lean and
    the steering are only the guess: the re-solve leaves them free (`UNMEASURED_STATES`);
    the roll rate is the plan's.

    A rider slower than the OCP's launch speed (`course_nlp.start_speed` for `settings`:
    stopped at a pause, or rolling off again) starts as at the start line instead: the
    launch speed at critical power, upright. A speed of 0 has no place in the OCP (its
    spatial ODE divides by the speed; the NLP bounds it below by `V_MIN_MPS`), and a
    rider held at the clipped 1 m/s with the 0 W a stopped power meter reads could not
    stay above that bound on a climb while the power ramps up at its rate limit.
    """
    x0 = dict(zip(planner.state_names, map(float, planner.initial_state(state, s_m)),
                  strict=True))
    plan = planner.plan
    rider = planner.rider
    launch = start_speed(rider, planner.conditions, settings or OcpSettings())
    if not state.speed_mps > launch:  # stopped (or no speed estimate): `free_states`
        # Along the line (a GPS heading at rest is noise), as at the start line.
        x0 |= {"v": launch, "w_n": rider.critical_power_w / rider.max_power_w,
               "alpha": float(plan.at("alpha_rad", s_m))}
        return Start(s_m=s_m, state={**x0, "phi": 0.0, "phi_dot": 0.0})
    return Start(s_m=s_m, state={**x0, "phi": float(plan.at("phi_rad", s_m)),
                                 "phi_dot": float(plan.at("phi_dot_radps", s_m))})


def plan_point(plan: Plan, settings: OcpSettings) -> tuple[PrimalDual | None, str]:
    """The primal-dual point a 3D re-solve from `plan` can start from: the plan's own
    (`plan.POINT_ARRAYS`) if it fits the re-solve's NLP on the plan's nodes (the worker
    solves the 3D model: a 1D plan's point has another layout), else None. Returns the
    point and, when there is none, why."""
    if plan.point_w is None or plan.point_lam_x is None or plan.point_lam_g is None:
        return None, "the plan carries no primal-dual point"
    if plan.model != "3d":
        return None, f"the plan's point is of the {plan.model} model, the re-solve is 3d"
    lay = course_layout("3d", settings.wprime_model, plan.n_nodes - 1)
    sizes = (len(plan.point_w), len(plan.point_lam_x), len(plan.point_lam_g))
    if sizes != (lay.n_var, lay.n_var, lay.n_g):
        return None, (f"the plan's point has sizes {sizes}, the NLP on its {plan.n_nodes} "
                      f"nodes {(lay.n_var, lay.n_var, lay.n_g)}")
    return PrimalDual(plan.s_m, plan.point_w, plan.point_lam_x, plan.point_lam_g), ""


class CourseReplanner:
    """One re-solve of the rest of the course at a time, in a worker process kept for
    the replanner's life (`_solve_in_worker`).

    Args:
        course, conditions: the road and what the planner assumes on it.
        settings: request period and solve settings.
        deterministic: adopt a result at a fixed stamp delay (module docstring).
        plan: the first plan in force: a re-solve from it starts from its primal-dual
            point if it carries one that fits (`plan_point`; why not: `cold_reason`).
    """

    def __init__(self, course: Course, conditions: Conditions, settings: CourseReplanSettings,
                 deterministic: bool, plan: Plan | None = None) -> None:
        self.course, self.conditions, self.settings = course, conditions, settings
        self.deterministic = deterministic
        # One thread that waits on the worker process (it runs no solver itself).
        self._waiter = ThreadPoolExecutor(max_workers=1, thread_name_prefix="course_replan")
        self._worker: subprocess.Popen[bytes] | None = None
        self._closed = threading.Event()
        self._pending: tuple[float, Future[tuple[Plan, PrimalDual | None]]] | None = None
        #: The last plan returned (or the first plan) and its primal-dual point: a
        #: re-solve from that plan starts from it (`solve_plan(warm=)`).
        self._point: tuple[Plan, PrimalDual] | None = None
        #: The point of the last 3D plan that had one: a 3D re-solve from a plan on the
        #: line starts from it (`resolve_model.Warm`).
        self._point_3d: PrimalDual | None = None
        #: Why the first plan's re-solve starts without its point ("" if it has one).
        self.cold_reason = ""
        if plan is not None:
            point, self.cold_reason = plan_point(plan, settings.ocp)
            self._keep_point(plan, point)
        #: The plan whose line a 1D re-solve rides (`RESOLVE_1D_LINE`): the last plan in
        #: force that is not itself such a re-solve (the first plan, a 3D plan).
        self._line_source: Plan | None = None
        #: Whether the last re-solve started was given a primal-dual point of its model.
        self.last_warm = False
        self._last_request_s = -math.inf
        #: Worker processes started so far (one per replanner unless one died).
        self.workers_started = 0
        #: Wall-clock seconds `take` waited for the worker, for benchmarks; never published.
        self.waited_s = 0.0

    def request(self, stamp_s: float, rider: Rider, guess: Plan, start: Start) -> bool:
        """Start a re-solve from `start` for `rider` unless one is pending, the last was
        asked for less than `period_s` ago, or the finish is near. Returns whether one
        was started."""
        st = self.settings
        if (st.period_s <= 0 or self._pending is not None
                or stamp_s - self._last_request_s < st.period_s
                or self.course.length_m - start.s_m < st.min_remaining_m):
            return False
        self._last_request_s = stamp_s
        own = self._point[1] if self._point is not None and self._point[0] is guess else None
        # A 3D plan in force without its own point (a failed re-solve since dropped it):
        # the last 3D plan's point, as after plans on the line.
        warm = (Warm(road_3d=self._point_3d, line=own) if on_line(guess)
                else Warm(road_3d=own if own is not None else self._point_3d))
        rest_m = self.course.length_m - start.s_m
        model = chosen_model(st.model, rest_m, st.auto_3d_max_m)
        self.last_warm = (warm.road_3d if model == RESOLVE_3D else warm.line) is not None
        line_n = None
        # The line the 1D re-solves (and the fall-back of a failed 3D one) ride: the last
        # 3D plan's, kept across 1D re-solves.
        if st.model != RESOLVE_3D:
            if self._line_source is None or not on_line(guess):
                self._line_source = guess
            src = self._line_source
            line_n = np.interp(self.course.s_m, src.s_m, src.n_m)
        free = free_states(start, start_speed(rider, self.conditions, st.ocp))
        job = (model, self.course, rider, self.conditions, st.ocp_for(model, rest_m), guess,
               start, warm, line_n, free)
        self._pending = (stamp_s, self._waiter.submit(self._solve_in_worker, job))
        return True

    def take(self, stamp_s: float) -> Plan | None:
        """The finished re-solve, once it is due (module docstring), else None.

        Raises:
            SolveError: the solve raised in the worker (its `SolveError` status, else
                "worker_exception", the error's type and text in the message), or the
                worker process died ("worker_failed"; the next request starts another).
                The caller logs it and goes on.
        """
        if self._pending is None:
            return None
        asked, future = self._pending
        if (not future.done() if not self.deterministic
                else stamp_s - asked < self.settings.delay_s - 1e-9):  # stamp rounding
            return None
        self._pending = None
        t0 = time.perf_counter()
        try:
            plan, point = future.result()  # a deterministic engine waits for a late worker
        finally:
            self.waited_s += time.perf_counter() - t0
        self._keep_point(plan, point)
        return plan

    def _keep_point(self, plan: Plan, point: PrimalDual | None) -> None:
        """Keep `plan`'s point for a re-solve from it, and for any 3D re-solve if it is a
        3D plan's."""
        self._point = None if point is None else (plan, point)
        if point is not None and plan.model == "3d":
            self._point_3d = point

    def _solve_in_worker(self, job: tuple[Any, ...]) -> tuple[Plan, PrimalDual | None]:
        """`solve_plan_point` on `job` in the worker process (`resolve_worker`), started
        at the first re-solve and kept for the next ones.

        Why a process: IPOPT's linear solver MUMPS is not thread-safe (Ipopt >= 3.14
        serialises its calls across threads, which would stall the horizon's solves
        behind the long one), and a crashing solver must not take the live node down.
        Why not `multiprocessing`: its "spawn" start re-runs the caller's main script
        in the child (a script without a main guard ran its ride again), and "fork" in
        a process with threads (ROS executors, the engine's inputs) can deadlock. Jobs
        and results travel as length-prefixed pickles over the worker's stdin and stdout.
        Why one process for all re-solves: a process per re-solve paid the imports and
        the model's symbolic build every time (~2-3 s of the 4-12 s a warm re-solve took
        on the Zwift Bologna ride; bench/RESULTS.md, 2026-12-02); a process kept keeps
        them, and the transcriptions of recent node counts (`course_nlp`'s cache).
        """
        worker = self._worker
        if worker is not None and worker.poll() is not None:
            # Died between re-solves: reported as if during one (never replaced silently).
            msg = f"the course re-solve worker had exited with code {self._drop_worker()}"
            raise SolveError(msg, status="worker_failed")
        if worker is None:
            worker = subprocess.Popen([sys.executable, "-c", WORKER_PROGRAM, str(os.getpid())],
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE)
            self._worker = worker
            self.workers_started += 1
            # `close` sets the flag, then kills the worker it sees: one started as it
            # closed is killed here (else it ran its whole solve, the node's exit waiting).
            if self._closed.is_set():
                worker.kill()
        assert worker.stdin is not None
        assert worker.stdout is not None
        try:
            send(worker.stdin, job)
            reply = receive(worker.stdout)
        except (OSError, EOFError):
            reply = None
        if reply is None:  # the worker died (or was killed by `close`)
            msg = f"the course re-solve worker exited with code {self._drop_worker()}"
            raise SolveError(msg, status="worker_failed")
        if reply[0] == "error":  # the solve raised in the worker, which goes on
            raise SolveError(reply[2], status=reply[1])
        result: tuple[Plan, PrimalDual | None] = reply[1]
        return result

    def _drop_worker(self) -> int | None:
        """Kill the worker if it runs, reap it, close its pipes; its exit code."""
        worker, self._worker = self._worker, None
        if worker is None:
            return None
        if worker.poll() is None:
            worker.kill()
        code = worker.wait()
        for pipe in (worker.stdin, worker.stdout):
            if pipe is not None:
                pipe.close()
        return code

    def close(self) -> None:
        """Stop now: a solve still running is abandoned (the worker killed)."""
        self._closed.set()
        self._drop_worker()
        self._waiter.shutdown(wait=False, cancel_futures=True)
        self._pending = None
