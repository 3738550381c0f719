"""What the pacing engine reports about itself: `EngineCounts` and its diagnostics.

`EngineCounts` is the read-only summary a replay or a node turns into warnings (nothing
the engine did not use is silent); the functions build the `/diagnostics` items of the
solver and of the inputs from the engine's counters.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from itt_planner.live.advice import Diagnostic, Level

#: Engine counters the solver diagnostic shows (the re-solves held back by
#: `resolve_gate` too: a re-solve not run is reported like one that failed).
_SOLVER_COUNTERS = ("solves", "failures", "overruns", "exceptions", "fallbacks",
                    "unconverged_solves", "course_replans_asked", "course_replans",
                    "course_replan_failures", "course_replans_backed_off",
                    "course_replans_skipped_stopped", "course_replan_backoffs",
                    "horizon_holds_standing")


@dataclass(frozen=True)
class EngineCounts:
    """What the engine did not use silently, for warnings (`PacingEngine.counts`).

    Attributes:
        advice: advices published; fallbacks: of them, the last good advice shifted.
        solves, solve_failures: horizon solves and those that failed, raised or overran.
        unconverged_solves: accepted horizon solves that did not converge (a
            budget-capped feasible iterate, "Suboptimal_Feasible").
        course_replans_asked, course_replans_adopted, course_replan_failures:
            re-solves of the rest of the course asked for, adopted, failed (a worker
            error or an unconverged solve: the plan in force stays).
        course_replans_backed_off, course_replans_skipped_stopped: re-solves the gate
            held (`resolve_gate`): the rider left each new plan at once, or stood.
        refits_up, refits_down: CP revisions (`cp_monitor`).
        cp_in_use_w, plan_version: the belief now (version 0: the first plan).
        plan_status, plan_converged: solver status of the plan in force.
    """

    advice: int
    fallbacks: int
    solves: int
    solve_failures: int
    unconverged_solves: int
    course_replans_asked: int
    course_replans_adopted: int
    course_replan_failures: int
    course_replans_backed_off: int
    course_replans_skipped_stopped: int
    refits_up: int
    refits_down: int
    cp_in_use_w: float
    plan_version: int
    plan_status: str
    plan_converged: bool


def solver_diagnostic(stamp_s: float, status: str, on_plan: bool, iterations: int,
                      failures: int, failures_for_error: int, stats: Mapping[str, int],
                      plan_version: int, plan_status: str,
                      solve_time_s: float | None) -> Diagnostic:
    """`itt_planner/solver`: the last replan's health (`failures` in a row: WARN, ERROR
    from `failures_for_error` on) and the counters; `solve_time_s` None in a
    deterministic engine (no wall-clock values)."""
    if on_plan:
        level, msg = Level.OK, "on the plan (W' within the band): no replan needed"
    elif stats.get("solves", 0) == 0:
        level, msg = Level.OK, "no solve yet"
    elif failures == 0:
        level, msg = Level.OK, f"solved ({status})"
    else:
        level = Level.ERROR if failures >= failures_for_error else Level.WARN
        msg = f"{failures} failed solve(s) in a row ({status}): last good advice in force"
    values = {"status": status, "iterations": str(iterations),
              "consecutive_failures": str(failures),
              **{k: str(stats.get(k, 0)) for k in _SOLVER_COUNTERS},
              "plan_version": str(plan_version), "plan_status": plan_status}
    if solve_time_s is not None:
        values["solve_time_s"] = f"{solve_time_s:.4f}"
    return Diagnostic(stamp_s, "itt_planner/solver", level, msg, values)


def input_diagnostics(stamp_s: float, sensors: Iterable[str], last_input: Mapping[str, float],
                      stale_after_s: float, rejects: Mapping[str, int],
                      reported: Mapping[str, int]) -> list[Diagnostic]:
    """Freshness per sensor (`sensors`: the estimator's hooks), and the inputs rejected
    since the last report (`reported`: the reject counts then)."""
    out = []
    for topic in sensors:
        seen = last_input.get(topic)
        if seen is None:
            out.append(Diagnostic(stamp_s, f"itt_planner/input/{topic}", Level.STALE,
                                  "no valid sample yet", {}))
            continue
        age = stamp_s - seen
        stale = age > stale_after_s
        out.append(Diagnostic(
            stamp_s, f"itt_planner/input/{topic}", Level.STALE if stale else Level.OK,
            f"stale: last valid sample {age:.1f} s ago" if stale else "fresh",
            {"age_s": f"{age:.3f}"}))
    new = {k: v - reported.get(k, 0) for k, v in rejects.items() if v > reported.get(k, 0)}
    out.append(Diagnostic(
        stamp_s, "itt_planner/inputs_rejected", Level.WARN if new else Level.OK,
        ("rejected since last report: " + ", ".join(f"{k}={v}" for k, v in sorted(new.items())))
        if new else "no rejected input since last report",
        {k: str(v) for k, v in sorted(rejects.items())}))
    return out
