"""A replayed ride log as arrays against time and distance, for the static report.

The report overlays what the rider did on the full-course plan, against distance. Only
the advice carries the rider's distance (its `state.s_m`, from the estimator inside the
pacing engine), so a log must be the output of `itt-planner replay` (or a recording of
the node): each power and speed sample is placed at the distance interpolated in time
between the advice states around it (the nearest state before the first and after the
last). A raw input log (`itt-planner import`, a demo bag) has no advice and is refused
with a message saying to replay it first: running the estimator here would be a second,
silent replay with none of the planner's output to compare against.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from itt_msgs_py import registry
from itt_planner.course.geometry import Course
from itt_planner.errors import IttError
from itt_planner.live.advice import Advice
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed
from itt_planner.logs.ridelog import SESSION_METADATA, RideLogReader

#: The first bytes of every MCAP file.
MCAP_MAGIC = b"\x89MCAP0\r\n"
#: A log ending this close to the finish line (projected) counts as a finished ride (m).
FINISH_TOLERANCE_M = 30.0


@dataclass(frozen=True, eq=False)
class RideTrace:
    """What a replayed ride log holds, as arrays; times in s from the first input message.

    Attributes:
        power_s_m, speed_s_m, gps_s_m: distance of each power / speed sample and GPS fix
            (see module doc).
        advice_*: one entry per advice, in stamp order; `cp_in_use_w`, `plan_version`
            and `cue` are what each advice says the engine planned with and told the
            rider (`belief_events` lists the refits and plan adoptions among them).
        metadata: the log's `itt_replay` record (input, course, rider, model ...), or {}.
    """

    path: Path
    start_stamp_s: float
    end_stamp_s: float
    power_t_s: np.ndarray
    power_w: np.ndarray
    power_s_m: np.ndarray
    speed_t_s: np.ndarray
    speed_mps: np.ndarray
    speed_s_m: np.ndarray
    gps_lat_deg: np.ndarray
    gps_lon_deg: np.ndarray
    gps_s_m: np.ndarray
    advice_t_s: np.ndarray
    advice_s_m: np.ndarray
    advice_speed_mps: np.ndarray
    target_power_w: np.ndarray
    w_prime_now_j: np.ndarray
    w_prime_finish_j: np.ndarray
    fallback: np.ndarray
    solver_status: tuple[str, ...]
    metadata: dict[str, str]
    cp_in_use_w: np.ndarray
    plan_version: np.ndarray
    cue: np.ndarray

    @property
    def duration_s(self) -> float:
        """Stamp time from the first to the last input message."""
        return self.end_stamp_s - self.start_stamp_s


def is_ride_log(path: str | Path) -> bool:
    """True for an `.mcap` name or a file starting with the MCAP magic (else: a plan)."""
    path = Path(path)
    if path.suffix.lower() == ".mcap":
        return True
    try:
        with path.open("rb") as file:
            return file.read(len(MCAP_MAGIC)) == MCAP_MAGIC
    except OSError:
        return False


def load_ride_trace(path: str | Path) -> RideTrace:
    """Read a replayed ride log into arrays.

    Raises:
        RideLogError: the file is not a readable MCAP ride log (names the file).
        IttError: the log has no advice (not a replay output). A ride without a power
            meter (GPS and speed only, which `replay` advises) has empty power arrays.
    """
    path = Path(path)
    reader = RideLogReader(path)
    # The records the report draws, by type (a sensor it does not draw only counts for
    # the ride's span).
    drawn: dict[type, list[Any]] = {PowerReading: [], WheelSpeed: [], GpsFix: [], Advice: []}
    first, last = math.inf, -math.inf
    for _topic, stamp_s, value in reader:
        if registry.is_sample(value):  # the ride's own span
            first, last = min(first, stamp_s), max(last, stamp_s)
        if type(value) in drawn:
            drawn[type(value)].append(value)
    power: list[PowerReading] = drawn[PowerReading]
    speed: list[WheelSpeed] = drawn[WheelSpeed]
    fixes: list[GpsFix] = drawn[GpsFix]
    advice: list[Advice] = drawn[Advice]
    if not advice:
        raise IttError(f"{path}: no advice in this log; the report of a ride needs a replay "
                       "output: run `itt-planner replay LOG --course C --rider R --out "
                       "OUT.mcap` and report OUT.mcap")
    advice.sort(key=lambda a: a.stamp_s)
    state_t = np.array([a.state.stamp_s for a in advice])
    state_s = np.array([a.state.s_m for a in advice])
    state_v = np.array([a.state.speed_mps for a in advice])
    reach_m = float(np.max(advice[-1].horizon_s_m, initial=state_s[-1]))
    power_t = np.array([p.stamp_s for p in power])
    speed_t = np.array([v.stamp_s for v in speed])
    gps_t = np.array([f.stamp_s for f in fixes])
    return RideTrace(
        path=path, start_stamp_s=first, end_stamp_s=last,
        power_t_s=power_t - first, power_w=np.array([p.power_w for p in power]),
        power_s_m=_distance_at(power_t, state_t, state_s, state_v, reach_m),
        speed_t_s=speed_t - first, speed_mps=np.array([v.speed_mps for v in speed]),
        speed_s_m=_distance_at(speed_t, state_t, state_s, state_v, reach_m),
        gps_lat_deg=np.array([f.lat_deg for f in fixes]),
        gps_lon_deg=np.array([f.lon_deg for f in fixes]),
        gps_s_m=_distance_at(gps_t, state_t, state_s, state_v, reach_m),
        advice_t_s=np.array([a.stamp_s for a in advice]) - first, advice_s_m=state_s,
        advice_speed_mps=np.array([a.state.speed_mps for a in advice]),
        target_power_w=np.array([a.target_power_w for a in advice]),
        w_prime_now_j=np.array([a.w_prime_now_j for a in advice]),
        w_prime_finish_j=np.array([a.w_prime_finish_j for a in advice]),
        fallback=np.array([a.fallback for a in advice]),
        solver_status=tuple(a.solver_status for a in advice),
        metadata=dict(reader.metadata.get(SESSION_METADATA, {})),
        cp_in_use_w=np.array([a.cp_in_use_w for a in advice]),
        plan_version=np.array([a.plan_version for a in advice], dtype=int),
        cue=np.array([int(a.cue) for a in advice], dtype=int))


@dataclass(frozen=True)
class BeliefEvent:
    """A change in what the engine planned with, as the advice reports it: a CP refit
    (`kind` "refit", CP before and after) or a plan adoption (`kind` "plan", the new
    version in `plan_version`)."""

    kind: str
    t_s: float
    s_m: float
    cp_before_w: float
    cp_after_w: float
    plan_version: int


def belief_events(trace: RideTrace) -> list[BeliefEvent]:
    """Every CP refit and plan adoption of a replayed ride, in order (from the advice's
    `cp_in_use_w` and `plan_version`, not from the rider or plan the report assumes)."""
    out = []
    cp, version = trace.cp_in_use_w, trace.plan_version
    for i in range(1, len(cp)):
        if cp[i] != cp[i - 1] and np.isfinite(cp[i]) and np.isfinite(cp[i - 1]):
            out.append(BeliefEvent("refit", float(trace.advice_t_s[i]),
                                   float(trace.advice_s_m[i]), float(cp[i - 1]), float(cp[i]),
                                   int(version[i])))
        if version[i] != version[i - 1]:
            out.append(BeliefEvent("plan", float(trace.advice_t_s[i]),
                                   float(trace.advice_s_m[i]), float(cp[i - 1]), float(cp[i]),
                                   int(version[i])))
    return out


def _distance_at(t_s: np.ndarray, state_t_s: np.ndarray, state_s_m: np.ndarray,
                 state_v_mps: np.ndarray, reach_m: float) -> np.ndarray:
    """Distance at stamps `t_s` from the advice states (see the module docstring)."""
    s = np.interp(t_s, state_t_s, state_s_m)
    period_s = float(state_t_s[-1] - state_t_s[-2]) if len(state_t_s) > 1 else 0.0
    after = np.clip(t_s - state_t_s[-1], 0.0, period_s)
    ahead = s + after * state_v_mps[-1]
    s_m: np.ndarray = np.where(after > 0, np.minimum(ahead, max(reach_m, state_s_m[-1])), s)
    return s_m


def actual_finish_s(trace: RideTrace, course: Course) -> float | None:
    """Time from the first input message to the finish line; None if it was not reached.

    The estimator's distance stops at the finish and advice comes once per replan
    period, so the crossing is extrapolated from the last advice state short of the line
    with that state's speed. A log that ends before the projected crossing still counts
    as finished when it ends less than `FINISH_TOLERANCE_M` from the line (the recording
    stops as the rider crosses; the last replan can be a period before that).
    """
    short = np.flatnonzero(trace.advice_s_m < course.length_m - 1.0)
    if len(short) == 0:
        return float(trace.advice_t_s[0])
    i = int(short[-1])
    v = max(float(trace.advice_speed_mps[i]), 0.1)
    crossing = float(trace.advice_t_s[i] + (course.length_m - trace.advice_s_m[i]) / v)
    if i + 1 < len(trace.advice_s_m):  # a later state is at the line: cross by then
        return min(crossing, float(trace.advice_t_s[i + 1]))
    left_at_end_m = (crossing - trace.duration_s) * v
    return crossing if left_at_end_m <= FINISH_TOLERANCE_M else None
