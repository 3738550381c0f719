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
    truth_rider = rider
    if scenario is Scenario.CP_OVERESTIMATED:
        truth_rider = dataclasses.replace(rider, critical_power_w=rider.critical_power_w
                                          * sc.cp_factor)
    par = ModelParams(truth_rider, conditions).vector()
    i_wind = PARAMS.index("wind_e")
    hot_start_m = min(sc.hot_start_m, course.length_m / 3)
    step = step_function(behaviour)
    rng_rider = np.random.default_rng([seed, 1])
    sens = Sensors(course, sensors, np.random.default_rng([seed, 2]), t0_s)
    engine = None
    if policy is Policy.REPLANNED:
        # Simulated time is not the wall clock: the engine's deterministic mode judges
        # nothing by wall time (overruns, when a re-solve of the course is ready).
        engine = PacingEngine(course, rider, plan,
                              conditions=planning_conditions(conditions, behaviour),
                              settings=dataclasses.replace(engine_settings, deterministic=True),
                              planner=planner)  # type: ignore[arg-type]
    grip = (behaviour.grip_lateral, conditions.mu_y)
    decel = behaviour.grip_brake * conditions.mu_x * GRAVITY_MPS2
    plan_ref = Reference.of_plan(course, plan, *grip)
    ref = plan_ref
    advice: list[Advice] = []
    samples: list[Sample] = []
    # Start as the plan does (model.md section 5): upright on the centre line, W_n = CP.
    x = np.zeros(8)
    x[4] = float(plan.v_mps[0])
    x[5] = rider.critical_power_w / rider.max_power_w
    x[7] = 1.0
    s, t = 0.0, 0.0
    noise = 0.0
    a_noise = math.exp(-dt_s / behaviour.power_noise_tau_s)
    limit = max_time_s if max_time_s is not None else 3.0 * plan.finish_time_s + 600.0
    rows = []
    finish = math.nan
    y = np.zeros(4)
    bar = tqdm(total=round(course.length_m), unit="m", desc=f"{scenario.value} {policy.value}",
               disable=not progress, file=sys.stderr, leave=False)
    while t < limit:
        bar.update(round(s) - bar.n)
        p_now = max(float(y[0]), 0.0)
        for smp in sens.sample(t, s, float(x[0]), float(x[4]), p_now):
            samples.append(smp)
            if engine is not None:
                engine.on_sample(smp)
        if engine is not None:
            adv = engine.update(t0_s + t)
            if adv is not None:
                advice.append(adv)
                ref = Reference.of_advice(course, adv, ref, *grip)
        rows.append((t, s, x[0], x[4], y[0], x[7] * truth_rider.w_prime_j, y[3]))
        # The rider's target at the current point.
        follow = plan_ref if (ref is plan_ref or s >= ref.s_m[-1]) else ref
        if scenario is Scenario.HOT_START and s < hot_start_m:
            follow = plan_ref
        # The rider reads the target one lag ahead, so the delivered power is on time.
        power, v_brake, n_ref, dn_ds, kappa_ff = follow.at(s, float(x[4]), behaviour, decel)
        # The rider brakes for speeds (the advised speed ahead, the grip envelope), by
        # hand and at once in the controller; a negative advised power only means "stop
        # pedalling" (braking it blindly, through the leg's lag, double-brakes a rider
        # who is already slower than the advice).
        power = max(power, 0.0)
        if policy is Policy.EVEN_CP:
            power = rider.critical_power_w
        if scenario is Scenario.HOT_START and s < hot_start_m:
            power *= sc.hot_start_factor
        noise = a_noise * noise + math.sqrt(1 - a_noise ** 2) * rng_rider.normal(
            0.0, behaviour.power_noise)
        w_cmd = (power * (1 + noise) / rider.max_power_w if power >= 0 else
                 power / (conditions.mu_x * GRAVITY_MPS2 * rider.mass_kg * max(x[4], 1.0)))
        road = road_vector(course, s)
        if scenario is Scenario.HEADWIND and s >= course.length_m / 2:
            # A head wind follows the road: blowing against the centre-line heading.
            par = par.copy()
            par[i_wind] = -sc.headwind_mps * math.cos(road[2])
            par[i_wind + 1] = -sc.headwind_mps * math.sin(road[2])
        x_next, s_next, y_next = step(x, s, road, par, [n_ref, dn_ds, w_cmd, v_brake, kappa_ff],
                                      dt_s)
        x_next = np.asarray(x_next).ravel()
        s_next = float(s_next)
        if s_next >= course.length_m:
            finish = t + dt_s * (course.length_m - s) / max(s_next - s, 1e-9)
            x, s, t, y = x_next, course.length_m, t + dt_s, np.asarray(y_next).ravel()
            rows.append((t, s, x[0], x[4], y[0], x[7] * truth_rider.w_prime_j, y[3]))
            break
        x, s, t, y = x_next, s_next, t + dt_s, np.asarray(y_next).ravel()
    bar.close()
    if engine is not None:
        engine.close()
    arr = np.array(rows)
    return SimResult(
        scenario=scenario, policy=policy, t_s=arr[:, 0], s_m=arr[:, 1], n_m=arr[:, 2],
        v_mps=arr[:, 3], power_w=arr[:, 4], w_prime_j=arr[:, 5], friction_use=arr[:, 6],
        samples=samples, advice=advice, finish_time_s=finish,
        solve_times_s=engine.solve_times_s if engine is not None else [],
        fallbacks=sum(a.fallback for a in advice),
        cp_in_use_w=engine.critical_power_w if engine is not None else math.nan,
    )
