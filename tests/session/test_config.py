"""`SessionConfig` is the flat edge form of the settings (one ROS parameter or CLI option
per field); its defaults must be those of the settings that own each value, or a node
and a library user would ride with different advice."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest
from support.courses import straight

from itt_planner.course.geometry import COURSE_SUFFIX, Course, GeoOrigin
from itt_planner.errors import IttError, RiderError, SolveError
from itt_planner.live.course_replan import CourseReplanSettings
from itt_planner.live.engine import EngineSettings
from itt_planner.model.conditions import Conditions, air_density_kgpm3
from itt_planner.model.rider import PRESETS
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.horizon_settings import HorizonSettings
from itt_planner.session.config import SessionConfig, build_engine
from itt_planner.session.ride_session import RideSession


def test_defaults_are_the_owners() -> None:
    config, engine = SessionConfig(), EngineSettings()
    assert config.horizon_m == HorizonSettings().horizon_m == CourseReplanSettings().min_remaining_m
    assert config.replan_period_s == engine.replan_period_s
    assert config.on_plan_band_j == engine.on_plan_band_j
    assert config.line_gate_m == engine.line_gate_m
    assert config.course_replan_period_s == CourseReplanSettings().period_s
    assert config.deterministic == engine.deterministic
    still = Conditions()
    assert (config.grip_mu, config.grip_mu) == (still.mu_x, still.mu_y)
    assert (config.wind_speed_mps, config.wind_from_rad) == (still.wind_speed_mps,
                                                             still.wind_from_rad)
    assert config.air_density_kgpm3 == still.air_density_kgpm3


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
    # Asked for other conditions, the session says the plan was not solved in them.
    with pytest.raises(SolveError, match=r"windy\.plan\.npz was solved in"):
        build_engine(SessionConfig(course=str(saved), rider="typical", plan=str(path),
                                   model="1d", wind_speed_mps=2.0))
    # A plan of another course (here 100 m longer) would be read on this one's distances.
    longer = straight(700.0).save(tmp_path / f"longer{COURSE_SUFFIX}")
    with pytest.raises(SolveError, match=r"windy\.plan\.npz was solved on course .*\(599 m\), "
                                         r"not on .*\(699 m\)"):
        build_engine(SessionConfig(course=str(longer), rider="typical", plan=str(path),
                                   model="1d"))


def test_a_session_plans_in_its_own_air_and_wind(tmp_path: Path) -> None:
    """`replay --air-density-kgpm3/--wind-kmh`, the node's parameters: the full-course
    plan and the horizon are solved in them. At 1,000 m in the paper's sea-level air the
    session warns (its set-up warnings, which the node logs at start); in the course's
    own air (ISA, 15 C: 1.09 kg/m^3) it does not."""
    flat = straight(600.0)
    high = Course.from_centerline("high", flat.x_m, flat.y_m, flat.z_m,
                                  origin=GeoOrigin(45.0, 11.0, 1000.0))
    saved = high.save(tmp_path / f"high{COURSE_SUFFIX}")
    base = SessionConfig(course=str(saved), rider="typical", model="1d",
                         plan_cache=str(tmp_path / "cache"), course_replan_period_s=0.0)
    for config, warned in ((base, True), (dataclasses.replace(
            base, air_density_kgpm3=1.09, wind_speed_mps=3.0, wind_from_rad=math.pi / 2,
            grip_mu=0.7), False)):
        engine = build_engine(config)
        session = RideSession(config, engine)
        try:
            asked = Conditions(mu_x=config.grip_mu, mu_y=config.grip_mu,
                               wind_speed_mps=config.wind_speed_mps,
                               wind_from_rad=config.wind_from_rad,
                               air_density_kgpm3=config.air_density_kgpm3)
            assert engine.horizon.planner.conditions == asked
            assert engine.plan.meta["conditions"] == dataclasses.asdict(asked)
            notes = session.setup_warnings()
            assert bool(notes) == warned, notes
            assert all("1.09" in n for n in notes)
        finally:
            session.close()


def test_a_logged_config_reads_back() -> None:
    """A session writes its config into its log as strings (`RideSession.describe`); the
    report reads it back to take the replay's plan. A field an older log lacks keeps its
    default (it ran with it); a value of the wrong type names the log and the field."""
    config = SessionConfig(course="c.gpx", rider="me.yaml", horizon_m=750.0,
                           wind_from_rad=1.5, deterministic=True, on_plan_band_j=0.0)
    logged = {k: str(v) for k, v in dataclasses.asdict(config).items()}
    assert SessionConfig.from_metadata(logged, "x.mcap") == config
    del logged["wind_from_rad"]
    assert SessionConfig.from_metadata(logged, "x.mcap").wind_from_rad == 0.0
    with pytest.raises(IttError, match=r"x\.mcap: session metadata horizon_m='far'"):
        SessionConfig.from_metadata({**logged, "horizon_m": "far"}, "x.mcap")
    with pytest.raises(IttError, match="deterministic='yes' is not a bool"):
        SessionConfig.from_metadata({**logged, "deterministic": "yes"}, "x.mcap")


def test_the_days_temperature_sets_the_air_at_the_courses_altitude() -> None:
    """`air_temperature_c` (the node's parameter, replay's `--air-temperature-c`): the
    air of ISA pressure at the course's mean altitude at that temperature; not given
    (NaN), the density asked for. Both given, or a temperature no race is ridden in, is
    refused by name."""
    hot = SessionConfig(air_temperature_c=35.0)
    assert hot.conditions(600.0).air_density_kgpm3 == pytest.approx(
        float(air_density_kgpm3(600.0, 35.0)))
    assert hot.conditions(600.0).air_density_kgpm3 < SessionConfig().conditions(600.0) \
        .air_density_kgpm3 == 1.23
    with pytest.raises(IttError, match=r"air_density_kgpm3 1\.1 and air_temperature_c 35\.0"):
        SessionConfig(air_temperature_c=35.0, air_density_kgpm3=1.1)
    with pytest.raises(RiderError, match=r"air temperature 80\.0 C"):
        SessionConfig(air_temperature_c=80.0).conditions(0.0)
    # Written into a log and read back: "nan" is "not given" again.
    logged = {k: str(v) for k, v in dataclasses.asdict(SessionConfig()).items()}
    assert logged["air_temperature_c"] == "nan"
    assert SessionConfig.from_metadata(logged, "x.mcap") == SessionConfig()
