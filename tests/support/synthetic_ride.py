"""A small synthetic ride for the Rerun and report tests: course, plan, samples, advice.

The course is a straight, a 90-degree left corner of radius 30 m and a climbing straight;
the plan is not an OCP solution but has the right shape (braking into the corner, slower
and leaning in it, W' spent on the climb), which is all the logging and plotting code
needs.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from itt_planner.course.geometry import Course, GeoOrigin
from itt_planner.live.advice import Advice, Diagnostic, Level
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed
from itt_planner.model.rider import PRESETS, Rider
from itt_planner.model.state import RiderState
from itt_planner.ocp.plan import PLAN_ARRAYS, Plan

ORIGIN = GeoOrigin(lat_deg=45.438, lon_deg=10.992, alt_m=60.0)
T0_S = 1_763_800_000.0  # a POSIX stamp (2025-11-22)
RIDER: Rider = PRESETS["paper"]
G = 9.81
#: The CP the synthetic ride's advice says was refitted (`make_ride`).
REFIT_CP_W = 0.95 * RIDER.critical_power_w


def make_course() -> Course:
    """300 m east, a 30 m radius left corner, 400 m north climbing 4 %."""
    x1 = np.linspace(0.0, 300.0, 301)
    a = np.linspace(-math.pi / 2, 0.0, 60)
    x2 = 300.0 + 30.0 * np.cos(a)
    y2 = 30.0 + 30.0 * np.sin(a)
    y3 = np.linspace(30.0, 430.0, 401)
    x = np.concatenate([x1, x2[1:], np.full(400, 330.0)])
    y = np.concatenate([np.zeros(301), y2[1:], y3[1:]])
    s_in = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    z = 60.0 + 0.04 * np.clip(s_in - 350.0, 0.0, None)
    return Course.from_centerline("synthetic-corner", x, y, z, origin=ORIGIN, synthetic=True,
                                  width_left_m=3.5, width_right_m=3.0)


def make_plan(course: Course, ds_m: float = 5.0) -> Plan:
    """A plausible plan on a `ds_m` grid (see the module docstring)."""
    s = np.arange(0.0, course.length_m, ds_m)
    kappa = course.at("kappa_per_m", s)
    grade = np.tan(course.at("beta_rad", s))
    v = np.minimum(14.0, np.sqrt(0.6 * G / np.maximum(np.abs(kappa), 1e-6)))
    v = np.convolve(np.pad(v, 4, mode="edge"), np.ones(9) / 9, mode="valid")
    v = v - 40.0 * np.clip(grade, 0.0, None)
    t = np.concatenate([[0.0], np.cumsum(np.diff(s) / v[:-1])])
    # Braking (negative power at the contact point, as an OCP plan) where it slows down.
    power = np.where(np.gradient(v, s) < -0.02, -1200.0,
                     380.0 + 2500.0 * np.clip(grade, 0.0, None))
    ay = v**2 * kappa
    phi = np.arctan(ay / G)
    w_prime = RIDER.w_prime_j - np.cumsum(np.maximum(power - RIDER.critical_power_w, 0.0)
                                          * np.gradient(t))
    n = 1.5 * np.sin(np.clip((s - 250.0) / 150.0, 0.0, 1.0) * math.pi)
    arrays: dict[str, Any] = {name: np.zeros_like(s) for name in PLAN_ARRAYS}
    arrays.update(s_m=s, t_s=t, n_m=n, phi_rad=phi, v_mps=v, power_w=power,
                  w_prime_j=w_prime, ay_mps2=ay, friction_use=np.abs(ay) / (0.8 * G))
    return Plan(model="3d", **arrays, solver_status="Solve_Succeeded", iterations=42,
                solve_time_s=1.5, meta={"course": course.name, "rider": RIDER.name})


def make_ride(course: Course, plan: Plan, *, rate_hz: float = 4.0
              ) -> list[GpsFix | WheelSpeed | PowerReading | RiderState | Advice
                        | list[Diagnostic]]:
    """The ride along the plan, as the engine would emit it, in stamp order.

    Power (what the rider pedals) and speed at `rate_hz`, GPS and rider states at 1 Hz,
    advice at 1 Hz (on the plan, no solve, for the first 10 s) with a step in target
    power half-way, a solver fallback at 40 s, diagnostics with one warning; the advice
    says CP was refitted to `REFIT_CP_W` at 60 % of the ride and a re-solved plan
    (version 1) adopted at 80 %.
    """
    events: list[GpsFix | WheelSpeed | PowerReading | RiderState | Advice
                 | list[Diagnostic]] = []
    duration = plan.finish_time_s
    for k in range(int(duration * rate_hz)):
        t = k / rate_hz
        s = float(np.interp(t, plan.t_s, plan.s_m))
        events.append(PowerReading(T0_S + t, float(plan.at("pedal_power_w", s))
                                   + 5.0 * math.sin(t)))
        events.append(WheelSpeed(T0_S + t, float(plan.at("v_mps", s))))
        if k % int(rate_hz):
            continue
        n = float(plan.at("n_m", s))
        x, y, z = course.enu_at(s, n)
        lat, lon, alt = course.to_geodetic(x, y, z)
        events.append(GpsFix(T0_S + t, float(lat), float(lon), float(alt), 3.0))
        state = RiderState(T0_S + t, s, n, float(plan.at("v_mps", s)), 0.0,
                           float(plan.at("pedal_power_w", s)), float(plan.at("w_prime_j", s)),
                           t)
        events.append(state)
        events.append(make_advice(course, plan, state, bump_w=25.0 if t > duration / 2 else 0.0,
                                  fallback=40.0 <= t < 42.0,
                                  cp_in_use_w=REFIT_CP_W if t >= 0.6 * duration
                                  else RIDER.critical_power_w,
                                  plan_version=int(t >= 0.8 * duration), solved=t >= 10.0))
        level = Level.WARN if 30.0 <= t < 35.0 else Level.OK
        events.append([
            Diagnostic(T0_S + t, "solver", level,
                       "solve overran budget" if level else "ok", {"iterations": "12"}),
            Diagnostic(T0_S + t, "inputs", Level.OK, "all inputs fresh"),
        ])
    return events


def make_advice(course: Course, plan: Plan, state: RiderState, *, bump_w: float = 0.0,
                fallback: bool = False, horizon_m: float = 300.0,
                cp_in_use_w: float = RIDER.critical_power_w, plan_version: int = 0,
                solved: bool = True) -> Advice:
    """Advice over `horizon_m` from `state`, taken from the plan's pedalling (+ `bump_w` of
    power): a solve's (`solved`), else the plan's own (status "on_plan", no solve)."""
    hs = np.linspace(state.s_m, min(state.s_m + horizon_m, course.length_m), 61)
    hn = plan.at("n_m", hs)
    x, y, z = course.enu_at(hs, hn)
    lat, lon, _ = course.to_geodetic(x, y, z)
    return Advice(
        stamp_s=state.stamp_s, state=state,
        target_power_w=float(plan.at("pedal_power_w", state.s_m)) + bump_w,
        horizon_s_m=hs, horizon_power_w=plan.at("pedal_power_w", hs) + bump_w,
        horizon_speed_mps=plan.at("v_mps", hs), horizon_n_m=hn, line_x_m=x, line_y_m=y,
        line_z_m=z, line_lat_deg=lat, line_lon_deg=lon,
        predicted_finish_s=plan.finish_time_s, w_prime_now_j=state.w_prime_j,
        w_prime_finish_j=float(plan.w_prime_j[-1]),
        solver_status="Solve_Succeeded" if solved else "on_plan", iterations=12 * solved,
        solve_time_s=(0.05 + 0.01 * math.sin(state.elapsed_s)) * solved, fallback=fallback,
        cp_in_use_w=cp_in_use_w, plan_version=plan_version,
    )
