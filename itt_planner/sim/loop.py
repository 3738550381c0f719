"""The closed loop of the virtual rider: sensors, engine, rider and the 3D model in time.

`simulate_ride` rides a course with a simulated rider whose truth (critical power, wind,
behaviour) may differ from what the planner believes. The rider follows advice (target
power with a lag and noise, the advised line with a path-following controller); the
sensors emit stamped `GpsFix` (1 Hz, 3 m noise), `WheelSpeed` and `PowerReading` samples;
the pacing engine turns them into advice. The dynamics are B's 3D model
(`model.build_3d`, E1-E9) converted from the spatial to the time domain
(`dx/dt = (dx/ds) / (dt/ds)`), so the simulator and the planner share one set of
equations.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from itt_planner.course.geometry import Course
from itt_planner.errors import IttError
from itt_planner.live.advice import Advice
from itt_planner.live.engine import EngineSettings, PacingEngine
from itt_planner.live.samples import Sample
from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.params import PARAMS, ModelParams
from itt_planner.model.rider import Rider
from itt_planner.ocp.plan import Plan
from itt_planner.sim.behaviour import RiderBehaviour, planning_conditions
from itt_planner.sim.reference import Reference
from itt_planner.sim.scenarios import Policy, Scenario, ScenarioSettings
from itt_planner.sim.sensors import Sensors, SensorSettings
from itt_planner.sim.step import road_vector, step_function


@dataclass(eq=False)
class SimResult:
    """One simulated ride: truth arrays over time, sensor samples, advice.

    Attributes:
        t_s, s_m, n_m, v_mps, power_w, w_prime_j, friction_use: the truth every step
            (`power_w` at the contact point, negative when braking; W' with the TRUE CP).
        samples: every sensor sample, in stamp order (what a bag of the ride holds).
        advice: every advice of the engine (replanned rides only).
        finish_time_s: time at the finish line (NaN when `max_time_s` ran out first).
        solve_times_s: wall-clock replan latencies of the engine.
        cp_in_use_w: the engine's CP at the finish (lower than the believed one after
            it refitted CP from a rider who could not hold the advice; NaN without engine).
    """

    scenario: Scenario
    policy: Policy
    t_s: np.ndarray
    s_m: np.ndarray
    n_m: np.ndarray
    v_mps: np.ndarray
    power_w: np.ndarray
    w_prime_j: np.ndarray
    friction_use: np.ndarray
    samples: list[Sample] = field(default_factory=list)
    advice: list[Advice] = field(default_factory=list)
    finish_time_s: float = math.nan
    solve_times_s: list[float] = field(default_factory=list)
    fallbacks: int = 0
    cp_in_use_w: float = math.nan

    def summary(self) -> dict[str, float]:
        """finish_time_s, w_prime_min_j, w_prime_end_j (and fallbacks, the engine's CP),
        JSON-ready."""
        return {"finish_time_s": round(float(self.finish_time_s), 3),
                "w_prime_min_j": round(float(self.w_prime_j.min()), 1),
                "w_prime_end_j": round(float(self.w_prime_j[-1]), 1),
                "max_friction_use": round(float(self.friction_use.max()), 3),
                "fallbacks": self.fallbacks,
                **({} if math.isnan(self.cp_in_use_w) else
                   {"cp_in_use_w": round(float(self.cp_in_use_w), 1)})}


def simulate_ride(course: Course, rider: Rider, plan: Plan, *,
                  scenario: Scenario | str = Scenario.NOMINAL, seed: int = 0,
                  policy: Policy | str = Policy.REPLANNED,
                  conditions: Conditions = Conditions(),
                  engine_settings: EngineSettings = EngineSettings(),
                  planner: object | None = None,
                  sensors: SensorSettings = SensorSettings(),
                  scenario_settings: ScenarioSettings = ScenarioSettings(),
                  behaviour: RiderBehaviour = RiderBehaviour(),
                  dt_s: float = 0.1, max_time_s: float | None = None,
                  t0_s: float = 0.0, progress: bool = False) -> SimResult:
    """Ride `course` in closed loop on the truth `conditions`.

    The planner believes `rider` and `planning_conditions(conditions, behaviour)`: the
    same road and air, with the lateral grip the rider uses; `plan` should be solved
    for those (then, in `nominal`, belief equals truth). The truth differs by
    `scenario`. With `policy=replanned` the sensor samples feed a
    `PacingEngine` (built on `planner`, a shared `HorizonPlanner` that keeps its own
    conditions - build it with `planning_conditions` - or its own), whose
    advice the rider follows from the moment it is published (the engine runs in its
    deterministic mode: simulated time is not the wall clock); the other policies follow
    the full-course `plan` or constant CP and need no engine. The rider's noise and the
    sensors draw from `seed`, identically for every policy, so policies compare on the
    same truth. `progress` draws a bar over the distance on stderr.

    Raises:
        IttError: unknown scenario or policy name.
    """
    try:
        scenario, policy = Scenario(scenario), Policy(policy)
    except ValueError as err:
        raise IttError(f"simulate: {err}") from None
    sc = scenario_settings
    truth_rider = _truth_rider(rider, scenario, sc)
    par = ModelParams(truth_rider, conditions).vector()
    hot_start_m = min(sc.hot_start_m, course.length_m / 3)
    step = step_function(behaviour)
    rng_rider = np.random.default_rng([seed, 1])
    sens = Sensors(course, sensors, np.random.default_rng([seed, 2]), t0_s)
    engine = (_engine(course, rider, plan, planning_conditions(conditions, behaviour),
                      engine_settings, planner) if policy is Policy.REPLANNED else None)
    grip = (behaviour.grip_lateral, conditions.mu_y)
    decel = behaviour.grip_brake * conditions.mu_x * GRAVITY_MPS2
    ref = plan_ref = Reference.of_plan(course, plan, *grip)
    advice: list[Advice] = []
    samples: list[Sample] = []
    x = _start_state(plan, rider)
    s, t, noise = 0.0, 0.0, 0.0
    a_noise = math.exp(-dt_s / behaviour.power_noise_tau_s)
    limit = max_time_s if max_time_s is not None else 3.0 * plan.finish_time_s + 600.0
    rows: list[tuple[float, ...]] = []
    finish, y = math.nan, np.zeros(4)
    bar = tqdm(total=round(course.length_m), unit="m", desc=f"{scenario.value} {policy.value}",
               disable=not progress, file=sys.stderr, leave=False)
    while t < limit:
        bar.update(round(s) - bar.n)
        adv = _sense(sens, engine, samples, t0_s + t, t, s, x, y)
        if adv is not None:
            advice.append(adv)
            ref = Reference.of_advice(course, adv, ref, *grip)
        rows.append((t, s, x[0], x[4], y[0], x[7] * truth_rider.w_prime_j, y[3]))
        # The rider's target at the current point (the plan's while riding a hot start).
        hot = scenario is Scenario.HOT_START and s < hot_start_m
        follow = plan_ref if (ref is plan_ref or s >= ref.s_m[-1] or hot) else ref
        # The rider reads the target one lag ahead, so the delivered power is on time.
        power, v_brake, n_ref, dn_ds, kappa_ff = follow.at(s, float(x[4]), behaviour, decel)
        power = _rider_power(power, policy, hot, rider, sc)
        noise = a_noise * noise + math.sqrt(1 - a_noise ** 2) * rng_rider.normal(
            0.0, behaviour.power_noise)
        w_cmd = (power * (1 + noise) / rider.max_power_w if power >= 0 else
                 power / (conditions.mu_x * GRAVITY_MPS2 * rider.mass_kg * max(x[4], 1.0)))
        road = road_vector(course, s)
        if scenario is Scenario.HEADWIND and s >= course.length_m / 2:
            par = _head_wind(par, road[2], sc.headwind_mps)
        x_next, s_next, y_next = step(x, s, road, par, [n_ref, dn_ds, w_cmd, v_brake, kappa_ff],
                                      dt_s)
        x_next, s_next = np.asarray(x_next).ravel(), float(s_next)
        if s_next >= course.length_m:
            finish = t + dt_s * (course.length_m - s) / max(s_next - s, 1e-9)
            x, s, t, y = x_next, course.length_m, t + dt_s, np.asarray(y_next).ravel()
            rows.append((t, s, x[0], x[4], y[0], x[7] * truth_rider.w_prime_j, y[3]))
            break
        x, s, t, y = x_next, s_next, t + dt_s, np.asarray(y_next).ravel()
    bar.close()
    return _result(scenario, policy, rows, samples, advice, finish, engine)


def _result(scenario: Scenario, policy: Policy, rows: list[tuple[float, ...]],
            samples: list[Sample], advice: list[Advice], finish_time_s: float,
            engine: PacingEngine | None) -> SimResult:
    """The ride's truth rows `(t, s, n, v, power, W', friction use)` as a `SimResult`;
    closes the engine."""
    if engine is not None:
        engine.close()
    arr = np.array(rows)
    return SimResult(
        scenario=scenario, policy=policy, t_s=arr[:, 0], s_m=arr[:, 1], n_m=arr[:, 2],
        v_mps=arr[:, 3], power_w=arr[:, 4], w_prime_j=arr[:, 5], friction_use=arr[:, 6],
        samples=samples, advice=advice, finish_time_s=finish_time_s,
        solve_times_s=engine.solve_times_s if engine is not None else [],
        fallbacks=sum(a.fallback for a in advice),
        cp_in_use_w=engine.critical_power_w if engine is not None else math.nan,
    )


def _truth_rider(rider: Rider, scenario: Scenario, sc: ScenarioSettings) -> Rider:
    """The rider as it really is: the believed one, but for its CP in `cp-overestimated`."""
    if scenario is Scenario.CP_OVERESTIMATED:
        return dataclasses.replace(rider, critical_power_w=rider.critical_power_w
                                   * sc.cp_factor)
    return rider


def _engine(course: Course, rider: Rider, plan: Plan, belief: Conditions,
            settings: EngineSettings, planner: object | None) -> PacingEngine:
    """The pacing engine of a replanned ride. Simulated time is not the wall clock: its
    deterministic mode judges nothing by wall time (overruns, when a re-solve of the
    course is ready)."""
    return PacingEngine(course, rider, plan, conditions=belief,
                        settings=dataclasses.replace(settings, deterministic=True),
                        planner=planner)  # type: ignore[arg-type]


def _start_state(plan: Plan, rider: Rider) -> np.ndarray:
    """Start as the plan does (model.md section 5): upright on the centre line, W_n = CP."""
    x = np.zeros(8)
    x[4] = float(plan.v_mps[0])
    x[5] = rider.critical_power_w / rider.max_power_w
    x[7] = 1.0
    return x


def _sense(sensors: Sensors, engine: PacingEngine | None, samples: list[Sample],
           stamp_s: float, t: float, s: float, x: np.ndarray, y: np.ndarray) -> Advice | None:
    """The samples due at ride time `t` (kept in `samples`, fed to the engine) and the
    engine's advice at `stamp_s`, if it has one."""
    p_now = max(float(y[0]), 0.0)
    for smp in sensors.sample(t, s, float(x[0]), float(x[4]), p_now):
        samples.append(smp)
        if engine is not None:
            engine.on_sample(smp)
    return engine.update(stamp_s) if engine is not None else None


def _rider_power(advised_w: float, policy: Policy, hot: bool, rider: Rider,
                 sc: ScenarioSettings) -> float:
    """The power the rider aims for. The rider brakes for speeds (the advised speed ahead,
    the grip envelope), by hand and at once in the controller; a negative advised power
    only means "stop pedalling" (braking it blindly, through the leg's lag, double-brakes
    a rider who is already slower than the advice)."""
    power = max(advised_w, 0.0)
    if policy is Policy.EVEN_CP:
        power = rider.critical_power_w
    if hot:
        power *= sc.hot_start_factor
    return power


def _head_wind(par: np.ndarray, heading_rad: float, wind_mps: float) -> np.ndarray:
    """The parameters with a head wind that follows the road: blowing against the
    centre-line heading."""
    i_wind = PARAMS.index("wind_e")
    par = par.copy()
    par[i_wind] = -wind_mps * math.cos(heading_rad)
    par[i_wind + 1] = -wind_mps * math.sin(heading_rad)
    return par
