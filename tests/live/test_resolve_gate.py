"""When the engine may ask for a re-solve of the rest of the course (`live.resolve_gate`):
the back-off for a rider who leaves every new plan, its reset, the stopped rider, and
every held request counted."""

from __future__ import annotations

from collections import Counter

from itt_planner.live.course_replan import CourseReplanSettings
from itt_planner.live.resolve_gate import ResolveGate

SETTINGS = CourseReplanSettings(period_s=30.0, delay_s=15.0, min_remaining_m=1000.0,
                                backoff_within_s=30.0, backoff_max_s=120.0)
LAUNCH_MPS = 1.0
RIDING_MPS = 10.0
FAR_M = 5000.0


def _ride(gate: ResolveGate, t0: float, t1: float, asked: list[float], *, off: bool = True,
          speed_mps: float = RIDING_MPS, remaining_m: float = FAR_M,
          adopt: bool = False, s_m: float = 0.0) -> list[float]:
    """One replan a second from `t0` to `t1`, off the plan (or on it); appends to `asked`
    the stamps at which a re-solve was asked (under the replanner's own period, as
    `CourseReplanner.request`) and returns it. `adopt`: each re-solve is adopted
    `delay_s` after it was asked (and the rider, off the plan, leaves it at once)."""
    for i in range(int(t1 - t0)):
        t = t0 + i
        if adopt and asked and t == asked[-1] + SETTINGS.delay_s:
            gate.adopted(t)
        if not off:
            gate.on_plan(t)
            continue
        gate.off_plan(t)
        period_ok = not asked or t - asked[-1] >= SETTINGS.period_s
        if (gate.allow(t, speed_mps, s_m, remaining_m) and period_ok
                and remaining_m >= SETTINGS.min_remaining_m):
            gate.asked(t)
            asked.append(t)
    return asked


def test_a_rider_who_leaves_every_new_plan_is_re_solved_less_often() -> None:
    """Each plan is left right after its adoption: the interval doubles up to its cap,
    and each request the plain period would have made and the gate held is counted."""
    stats: Counter[str] = Counter()
    gate = ResolveGate(SETTINGS, LAUNCH_MPS, stats)
    asked = _ride(gate, 0.0, 600.0, [], adopt=True)
    # Adopted at 15 s and left: 60 s; at 75: 120 s (the cap); then every 120 s.
    assert asked == [0.0, 60.0, 180.0, 300.0, 420.0, 540.0]
    assert gate.interval_s == 120.0
    assert stats["course_replan_backoffs"] == 6  # a doubling (or held at the cap) each
    # The plain 30 s period would have asked 20 times (0, 30, ... 570): 14 held.
    assert stats["course_replans_backed_off"] == 14
    assert stats["course_replans_skipped_stopped"] == 0


def test_back_off_counts_every_held_request() -> None:
    """With the interval at 120 s and the rider off the plan throughout, the gate holds
    three of every four requests the 30 s period would make, and counts them."""
    stats: Counter[str] = Counter()
    gate = ResolveGate(SETTINGS, LAUNCH_MPS, stats)
    gate.interval_s = 120.0
    assert _ride(gate, 0.0, 480.0, []) == [0.0, 120.0, 240.0, 360.0]
    assert stats["course_replans_backed_off"] == 12  # 30, 60, 90, 150, ... 450


def test_a_rider_who_keeps_to_the_new_plan_resets_the_back_off() -> None:
    stats: Counter[str] = Counter()
    gate = ResolveGate(SETTINGS, LAUNCH_MPS, stats)
    gate.adopted(0.0)
    gate.off_plan(5.0)
    assert gate.interval_s == 60.0
    gate.adopted(100.0)
    _ride(gate, 100.0, 131.0, [], off=False)  # inside the band for 30 s
    assert gate.interval_s == SETTINGS.period_s
    gate.adopted(200.0)
    gate.off_plan(240.0)  # left it, but after keeping to it for 40 s
    assert gate.interval_s == SETTINGS.period_s
    gate.adopted(300.0)
    gate.off_plan(301.0)
    gate.reset()  # a CP refit: a new belief
    assert gate.interval_s == SETTINGS.period_s
    assert stats["course_replan_backoffs"] == 2


def test_a_stopped_rider_is_re_solved_from_once_per_stop() -> None:
    """Stopped (at or below the launch speed): one re-solve at once, even backed off;
    then held and counted once per period while the rider stands; riding again, the
    usual rules; a later stop elsewhere gets its own."""
    stats: Counter[str] = Counter()
    gate = ResolveGate(SETTINGS, LAUNCH_MPS, stats)
    gate.interval_s = SETTINGS.backoff_max_s
    asked = _ride(gate, 0.0, 130.0, [], speed_mps=0.0, s_m=8175.0)
    assert asked == [0.0]
    assert stats["course_replans_skipped_stopped"] == 4  # 30, 60, 90, 120
    assert _ride(gate, 130.0, 140.0, asked, speed_mps=LAUNCH_MPS, s_m=8176.0) == [0.0]
    assert _ride(gate, 140.0, 150.0, asked) == [0.0, 140.0]  # riding: 140 s >= interval
    assert _ride(gate, 200.0, 210.0, asked, speed_mps=0.0, s_m=9000.0) == [0.0, 140.0, 200.0]
    assert stats["course_replans_backed_off"] == 0


def test_nothing_held_where_the_replanner_would_not_ask() -> None:
    """Re-solving off, or near the finish: the gate lets the replanner decline, and
    counts nothing."""
    stats: Counter[str] = Counter()
    near = ResolveGate(SETTINGS, LAUNCH_MPS, stats)
    assert _ride(near, 0.0, 100.0, [], speed_mps=0.0, remaining_m=500.0) == []
    off = ResolveGate(CourseReplanSettings(period_s=0.0), LAUNCH_MPS, stats)
    assert off.allow(0.0, 0.0, 0.0, FAR_M)
    assert not stats
