"""`SessionConfig` is the flat edge form of the settings (one ROS parameter or CLI option
per field); its defaults must be those of the settings that own each value, or a node
and a library user would ride with different advice."""

from __future__ import annotations

from itt_planner.live.course_replan import CourseReplanSettings
from itt_planner.live.engine import EngineSettings
from itt_planner.ocp.horizon_settings import HorizonSettings
from itt_planner.session.config import SessionConfig


def test_defaults_are_the_owners() -> None:
    config, engine = SessionConfig(), EngineSettings()
    assert config.horizon_m == HorizonSettings().horizon_m == CourseReplanSettings().min_remaining_m
    assert config.replan_period_s == engine.replan_period_s
    assert config.on_plan_band_j == engine.on_plan_band_j
    assert config.line_gate_m == engine.line_gate_m
    assert config.course_replan_period_s == CourseReplanSettings().period_s
    assert config.deterministic == engine.deterministic
