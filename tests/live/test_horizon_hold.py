"""The horizon holds its last solve for a standing rider (`live.horizon_step`): a rider
stopped on the road is solved for once, advised that solve while standing (not a
fallback, counted), solved again at least every `_HOLD_S`, and at once on rolling off.
Real planner on the hairpin test course."""

from __future__ import annotations

import numpy as np
import pytest
from support.hairpin_fixtures import PLAN_CONDITIONS, RIDER

from itt_planner.course.geometry import Course
from itt_planner.live.advice import Advice
from itt_planner.live.course_replan import CourseReplanSettings
from itt_planner.live.engine import EngineSettings, PacingEngine
from itt_planner.live.horizon_step import _HOLD_S, HELD_STANDING
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed
from itt_planner.ocp.horizon import HorizonPlanner
from itt_planner.ocp.horizon_settings import HorizonSettings
from itt_planner.ocp.plan import Plan

#: As in test_engine: a short horizon, no wall-time judgements; replans every period
#: (no advice on the plan) and no re-solves of the course (no worker process).
CALM = HorizonSettings(horizon_m=400.0, n_intervals=50, max_wall_time_s=30.0)
SETTINGS = EngineSettings(max_solve_time_s=30.0, on_plan_band_j=0.0, deterministic=True,
                          course_replan=CourseReplanSettings(period_s=0.0))


def _at(engine: PacingEngine, course: Course, t: float, s: float, v: float, p: float
        ) -> Advice | None:
    lat, lon, alt = (float(a) for a in course.to_geodetic(*course.enu_at(s, 0.0)))
    engine.on_sample(GpsFix(t, lat, lon, alt))
    engine.on_sample(WheelSpeed(t, v))
    engine.on_sample(PowerReading(t, p))
    return engine.update(t)


def test_a_standing_rider_is_held_on_the_last_solve(course: Course, plan: Plan) -> None:
    planner = HorizonPlanner(course, RIDER, plan, conditions=PLAN_CONDITIONS, settings=CALM)
    engine = PacingEngine(course, RIDER, plan, settings=SETTINGS, planner=planner)
    s_stop = 60.0
    standing = [a for t in range(45) if (a := _at(engine, course, float(t), s_stop, 0.0, 0.0))]
    # Rolling off: 3 m/s, 250 W, moving along the course.
    rolling = [a for k in range(3) if (a := _at(engine, course, 45.0 + k,
                                                  s_stop + 3.0 * (k + 1), 3.0, 250.0))]
    counters = engine.counters
    solver = {d.name: d for d in engine.diagnostics(47.0)}["itt_planner/solver"]
    engine.close()
    solved = [a for a in standing if a.solver_status != HELD_STANDING]
    held = [a for a in standing if a.solver_status == HELD_STANDING]
    assert standing[0] in solved and standing[0].iterations > 0
    assert not any(a.fallback for a in standing + rolling)
    # One solve per `_HOLD_S` of standing at most (here 45 s: the first and one more).
    assert len(solved) == int(np.ceil(45.0 / _HOLD_S))
    assert counters["horizon_holds_standing"] == len(held) == 45 - len(solved)
    assert counters["solves"] == len(solved) + len(rolling)
    # Held advice is on /diagnostics too, like every other held work.
    assert solver.values["horizon_holds_standing"] == str(len(held))
    for a in held:  # the solve's advice, cut where the rider stands
        first = max((b for b in solved if b.stamp_s < a.stamp_s), key=lambda b: b.stamp_s)
        assert a.iterations == 0
        assert a.target_power_w == pytest.approx(first.target_power_w, abs=1.0)
        np.testing.assert_allclose(a.horizon_power_w[1:], first.horizon_power_w[1:],
                                   atol=1.0)
        assert a.target_power_w >= 0.0
    assert all(a.solver_status != HELD_STANDING and a.iterations > 0 for a in rolling)
