"""`SessionConfig` is the flat edge form of the settings (one ROS parameter or CLI option
per field); its defaults must be those of the settings that own each value, or a node
and a library user would ride with different advice."""

from __future__ import annotations

from pathlib import Path

from support.courses import straight

from itt_planner.course.geometry import COURSE_SUFFIX
from itt_planner.live.course_replan import CourseReplanSettings
from itt_planner.live.engine import EngineSettings
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import PRESETS
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.horizon_settings import HorizonSettings
from itt_planner.session.config import SessionConfig, build_engine


def test_defaults_are_the_owners() -> None:
    config, engine = SessionConfig(), EngineSettings()
    assert config.horizon_m == HorizonSettings().horizon_m == CourseReplanSettings().min_remaining_m
    assert config.replan_period_s == engine.replan_period_s
    assert config.on_plan_band_j == engine.on_plan_band_j
    assert config.line_gate_m == engine.line_gate_m
    assert config.course_replan_period_s == CourseReplanSettings().period_s
    assert config.deterministic == engine.deterministic


def test_a_given_plan_brings_its_conditions(tmp_path: Path) -> None:
    """A plan solved in a wind, given to a session (`--plan`, the node's `plan`), is
    re-planned by the horizon in that wind, not in still air."""
    course = straight(600.0)
    saved = course.save(tmp_path / f"straight{COURSE_SUFFIX}")
    windy = Conditions.from_meteo(wind_kmh=20.0, wind_from_deg=90.0, mu=0.8)
    plan = solve_plan(course, PRESETS["typical"], windy, model="1d")
    path = plan.save(tmp_path / "windy.plan.npz")
    engine = build_engine(SessionConfig(course=str(saved), rider="typical", plan=str(path),
                                        model="1d", course_replan_period_s=0.0))
    try:
        assert engine.horizon.planner.conditions == windy
    finally:
        engine.close()
