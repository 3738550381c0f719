"""The three policies (replanned, open loop, even CP) ridden on the same truth, and the
figures `itt-planner simulate` prints."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.live.engine import EngineSettings
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import Rider
from itt_planner.ocp.plan import Plan
from itt_planner.sim.behaviour import RiderBehaviour, planning_conditions
from itt_planner.sim.loop import simulate_ride
from itt_planner.sim.scenarios import Policy, Scenario


def compare_policies(course: Course, rider: Rider, plan: Plan, *,
                     scenario: Scenario | str = Scenario.NOMINAL, seed: int = 0,
                     conditions: Conditions = Conditions(),
                     engine_settings: EngineSettings = EngineSettings(),
                     planner: object | None = None,
                     behaviour: RiderBehaviour = RiderBehaviour(),
                     **kwargs: object) -> dict[str, Any]:
    """The three policies on the same truth, and the figures `itt-planner simulate` prints.

    `behaviour` and `kwargs` go to `simulate_ride` (sensors, scenario settings, dt_s).
    Margins are positive when the replanned ride is faster. `plan_finish_time_s` is the
    full-course optimum for the conditions `plan` was solved for: for the grip the
    rider uses when those are `planning_conditions` (`plan_for_rider_grip` says whether
    they are, from the plan's metadata; a plan cornering at full grip is one this
    rider cannot follow).

    Raises:
        IttError: unknown scenario.
    """
    runs = {policy: simulate_ride(course, rider, plan, scenario=scenario, seed=seed,
                                  policy=policy, conditions=conditions,
                                  engine_settings=engine_settings, planner=planner,
                                  behaviour=behaviour, **kwargs)  # type: ignore[arg-type]
            for policy in Policy}
    replanned = runs[Policy.REPLANNED]
    lat = np.array(replanned.solve_times_s) if replanned.solve_times_s else np.zeros(1)
    t_re = replanned.finish_time_s
    believed = dataclasses.asdict(planning_conditions(conditions, behaviour))
    return {
        "course": course.name, "rider": rider.name, "scenario": Scenario(scenario).value,
        "seed": seed,
        "plan_finish_time_s": round(plan.finish_time_s, 3),
        "plan_for_rider_grip": plan.meta.get("conditions") == believed,
        **{p.value: runs[p].summary() for p in Policy},
        "margins": {
            "replanned_vs_open_loop_s": round(runs[Policy.OPEN_LOOP].finish_time_s - t_re, 3),
            "replanned_vs_even_cp_s": round(runs[Policy.EVEN_CP].finish_time_s - t_re, 3),
            "replanned_vs_plan_pct": round(100 * (t_re / plan.finish_time_s - 1), 3),
        },
        "replan_latency_s": {"median": round(float(np.median(lat)), 4),
                             "p95": round(float(np.percentile(lat, 95)), 4),
                             "max": round(float(lat.max()), 4)},
        "replans": len(replanned.solve_times_s),
    }
