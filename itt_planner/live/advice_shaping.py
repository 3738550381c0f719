"""Advice a rider can follow: the planner's power turned into a target power and a cue.

The planner's power (`horizon_power_w`) is the power at the contact point of model.md
section 2: negative where the plan brakes (a braking force times the speed, -4 kW at a
tight corner on a real descent), and free to jump between two replans (each is a new
optimum from a noisy state: 17 steps over 200 W between consecutive seconds on a real
ride). A head unit can show neither. `AdviceShaper` makes of it:

- a `Cue` (`advice.Cue`): BRAKE where the plan brakes within the next advice period
  (its power there below `-brake_fraction` x CP), COAST where its mean power is below
  `coast_fraction` x CP (a lean too deep to pedal, C15, or a descent; left again only
  above twice that, so noise does not flicker the cue), CLIMB over the foot of a climb
  (`climb_starts`), PEDAL otherwise;
- a target power >= 0 W: 0 while coasting or braking, else the plan's mean power over
  the next advice period, moved from the last target by at most the rider's maximal
  power rate `vW_max` (model.md section 7, `Rider.power_rate_max_wps`, 50 W/s) times
  the time since the last advice (at most `max_step_s` of it). Why that rate: it is the
  reference rate of the OCP's power command (E6), what the plans themselves assume a
  rider ramps at. The target jumps straight to the plan's power only at a documented
  cue: a corner exit (COAST/BRAKE -> PEDAL or CLIMB), the entry into a coast or brake
  (the target drops to 0 with the cue) and a climb start (-> CLIMB);
- the advised speed at the apex of the next corner (`Course.corners`) within the
  horizon, and the distance to it.

`advice_steps` measures the result on any advice stream (a replay's output, a
simulation): every step over a threshold between consecutive advices, with the cue
change that explains it, or none.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.live.advice import Advice, Cue

#: A target step larger than this (W) between consecutive advices must have a cue.
STEP_LIMIT_W = 100.0
_STOPPED = (Cue.COAST, Cue.BRAKE)


@dataclass(frozen=True)
class ShapingSettings:
    """How the planner's power becomes a target and a cue.

    Attributes:
        coast_fraction: mean planned power below this fraction of CP is a COAST cue
            (left again above twice it).
        brake_fraction: planned power below minus this fraction of CP within the next
            advice period is a BRAKE cue (left again above half of it).
        max_step_s: the rate limit allows at most this much time's worth of change in
            one step (a gap in the advice stream is no licence for a jump): 2 s at
            50 W/s is the 100 W of `STEP_LIMIT_W`.
        lookahead_s: the target is the plan's mean power over this much travel from
            the rider (the replan period: what the rider rides until the next advice).
        climb_grade: a climb is where the grade, averaged over `climb_window_m` ahead,
            reaches this (0.04: 4 %) ...
        climb_window_m: ... (the averaging length) ...
        climb_min_m: ... and stays at least that steep this far;
        climb_cue_m: the CLIMB cue holds from this far before the foot of a climb to as
            far past it (the plan raises its power on the approach).
    """

    coast_fraction: float = 0.10
    brake_fraction: float = 0.10
    max_step_s: float = 2.0
    lookahead_s: float = 1.0
    climb_grade: float = 0.04
    climb_window_m: float = 100.0
    climb_min_m: float = 200.0
    climb_cue_m: float = 50.0


def climb_starts(course: Course, settings: ShapingSettings = ShapingSettings()) -> np.ndarray:
    """Arc lengths of the feet of the climbs: where the grade averaged over the next
    `climb_window_m` rises through `climb_grade` and stays above it `climb_min_m`."""
    st = settings
    s = course.s_m
    ds = float(course.ds_m)
    k = max(round(st.climb_window_m / ds), 1)
    grade = np.tan(course.beta_rad)
    ahead = np.convolve(np.pad(grade, (0, k), mode="edge"), np.ones(k) / k, mode="valid")[:len(s)]
    steep = ahead >= st.climb_grade
    rises = np.flatnonzero(steep[1:] & ~steep[:-1]) + 1
    if len(s) and steep[0]:
        rises = np.concatenate([[0], rises])
    run = max(round(st.climb_min_m / ds), 1)
    return np.array([s[i] for i in rises if steep[i:i + run].all()], dtype=float)


class AdviceShaper:
    """Keeps the last published target and cue; `shape` makes the next ones.

    Args:
        course: corners and climbs.
        power_rate_wps: the rider's maximal power rate (`Rider.power_rate_max_wps`).
        settings: thresholds.
    """

    def __init__(self, course: Course, power_rate_wps: float,
                 settings: ShapingSettings = ShapingSettings()) -> None:
        self.course = course
        self.power_rate_wps = power_rate_wps
        self.settings = settings
        self._climbs = climb_starts(course, settings)
        self._apex = np.array([c.apex_s_m for c in course.corners], dtype=float)
        self._entry = np.array([c.entry_s_m for c in course.corners], dtype=float)
        self._exit = np.array([c.exit_s_m for c in course.corners], dtype=float)
        self._last: tuple[float, float, Cue] | None = None  # (stamp, target, cue)

    def reset(self) -> None:
        """Forget the last target (after a restart the first target is not rate-limited)."""
        self._last = None

    def shape(self, stamp_s: float, s_m: float, speed_mps: float, cp_w: float,
              horizon_s_m: np.ndarray, horizon_power_w: np.ndarray,
              horizon_speed_mps: np.ndarray) -> dict[str, Any]:
        """Target power, cue and next-corner fields of one advice (the `Advice` keyword
        arguments `target_power_w`, `cue`, `corner_speed_mps`, `corner_distance_m`)."""
        st = self.settings
        reach = max(speed_mps, 1.0) * st.lookahead_s
        end = min(s_m + reach, float(horizon_s_m[-1]))
        inside = horizon_s_m[(horizon_s_m > s_m) & (horizon_s_m < end)]
        grid = np.concatenate([[s_m], inside, [end]]) if end > s_m else np.array([s_m])
        if len(horizon_s_m) > 1:
            planned = np.interp(grid, horizon_s_m, horizon_power_w)
            if len(grid) == 1:  # no travel ahead within the horizon: the next node
                planned = horizon_power_w[1:2]
            # A mean over travel (not over nodes: the grid is uneven).
            mean = (float(np.trapezoid(planned, grid) / (grid[-1] - grid[0]))
                    if len(grid) > 1 else float(planned[0]))
            low = float(planned[1:].min()) if len(planned) > 1 else float(planned[0])
        else:
            mean = low = float(horizon_power_w[0])
        cue = self._cue(mean, low, s_m, cp_w)
        target = 0.0 if cue in _STOPPED else max(mean, 0.0)
        last = self._last
        if last is not None and cue not in _STOPPED and last[2] not in _STOPPED and not (
                cue is Cue.CLIMB and last[2] is not Cue.CLIMB):
            dt = min(max(stamp_s - last[0], 0.0), st.max_step_s)
            limit = self.power_rate_wps * dt
            target = min(max(target, last[1] - limit), last[1] + limit)
        self._last = (stamp_s, target, cue)
        speed, distance = self._next_corner(s_m, horizon_s_m, horizon_speed_mps)
        return {"target_power_w": float(target), "cue": cue, "corner_speed_mps": speed,
                "corner_distance_m": distance}

    def _cue(self, mean_w: float, low_w: float, s_m: float, cp_w: float) -> Cue:
        st = self.settings
        was = self._last[2] if self._last is not None else Cue.PEDAL
        brake = st.brake_fraction * cp_w
        if low_w < -(0.5 * brake if was is Cue.BRAKE else brake):
            return Cue.BRAKE
        if mean_w < st.coast_fraction * cp_w * (2.0 if was in _STOPPED else 1.0):
            return Cue.COAST
        near: np.ndarray | list[bool] = (np.abs(self._climbs - s_m) <= st.climb_cue_m
                                         if len(self._climbs) else [])
        return Cue.CLIMB if np.any(near) else Cue.PEDAL

    def _next_corner(self, s_m: float, horizon_s_m: np.ndarray,
                     horizon_speed_mps: np.ndarray) -> tuple[float, float]:
        """(advised speed at the apex, distance to it) of the next corner whose apex is
        ahead and within the horizon; (nan, nan) when none. The speed is the lowest
        advised between the corner's entry and its apex (the apex of the line, where the
        rider is slowest, can lie before the road's tightest point)."""
        ahead = np.flatnonzero(self._apex >= s_m)
        if len(ahead) == 0 or len(horizon_s_m) < 2:
            return math.nan, math.nan
        i = int(ahead[0])
        apex = float(self._apex[i])
        if apex > float(horizon_s_m[-1]):
            return math.nan, math.nan
        lo = max(float(self._entry[i]), s_m)
        probe = np.linspace(lo, apex, 9)
        speed = float(np.interp(probe, horizon_s_m, horizon_speed_mps).min())
        return speed, apex - s_m


@dataclass(frozen=True)
class Step:
    """A target-power step between two consecutive advices.

    `reason` is the cue change that explains it ("corner_exit", "coast", "brake",
    "climb_start"), or "" when nothing does (a step the rider cannot follow).
    """

    stamp_s: float
    s_m: float
    from_w: float
    to_w: float
    reason: str

    @property
    def size_w(self) -> float:
        return abs(self.to_w - self.from_w)


def step_reason(before: Cue, after: Cue) -> str:
    """The documented cue change that licenses a large target step, or ""."""
    if before in _STOPPED and after not in _STOPPED:
        return "corner_exit"
    if after is Cue.BRAKE and before is not Cue.BRAKE:
        return "brake"
    if after is Cue.COAST and before not in _STOPPED:
        return "coast"
    if after is Cue.CLIMB and before is not Cue.CLIMB:
        return "climb_start"
    return ""


def advice_steps(advice: Sequence[Advice], limit_w: float = STEP_LIMIT_W) -> list[Step]:
    """Every step over `limit_w` between consecutive advices (in stamp order), each with
    its reason (`step_reason`; "" when no cue explains it)."""
    out = []
    for a, b in itertools.pairwise(advice):
        if abs(b.target_power_w - a.target_power_w) > limit_w:
            out.append(Step(b.stamp_s, b.state.s_m, a.target_power_w, b.target_power_w,
                            step_reason(Cue(a.cue), Cue(b.cue))))
    return out


def advice_stats(advice: Sequence[Advice], limit_w: float = STEP_LIMIT_W) -> dict[str, Any]:
    """JSON-able figures of an advice stream: the lowest target, steps over `limit_w`
    (all, and those no cue explains), fallbacks, cues, refits seen as CP changes and
    plan adoptions seen as plan-version changes."""
    steps = advice_steps(advice, limit_w)
    by_reason: dict[str, int] = {}
    for st in steps:
        key = st.reason or "unexplained"
        by_reason[key] = by_reason.get(key, 0) + 1
    cues = {c.name.lower(): sum(int(a.cue) == c for a in advice) for c in Cue}
    cp = [a.cp_in_use_w for a in advice]
    return {
        "advice": len(advice),
        "min_target_power_w": min((a.target_power_w for a in advice), default=math.nan),
        "steps_over_limit": len(steps), "step_limit_w": limit_w,
        "unexplained_steps": by_reason.get("unexplained", 0), "steps_by_reason": by_reason,
        "fallbacks": sum(bool(a.fallback) for a in advice),
        "fallback_fraction": (sum(bool(a.fallback) for a in advice) / len(advice)
                              if advice else 0.0),
        "cues": cues,
        "cp_changes": sum(1 for x, y in itertools.pairwise(cp) if x != y and math.isfinite(x)),
        "plan_versions": len({a.plan_version for a in advice}),
        "min_w_prime_now_j": min((a.w_prime_now_j for a in advice), default=math.nan),
    }
