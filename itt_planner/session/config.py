"""What decides a session's advice, the engine built from it, and the plan a logged
session had.

`SessionConfig` is loaded once at the edge (CLI options or ROS parameters: the node
declares one parameter per field); `build_engine` loads the course, rider and full-course
plan (`session_plan`: a plan file, else the plan cache's) and builds the `PacingEngine`
with its horizon planner. A session writes its config into its log; `ride_setup` reads
it back (`SessionConfig.from_metadata`) for the ride's report.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from itt_msgs_py import DEFAULT_NAMESPACE
from itt_planner.errors import IttError, SolveError
from itt_planner.model.rider import PAPER_AIR_DENSITY_KGPM3

#: A plan's finish within this of the course's is on the same course (a plan ends at the
#: course's last point; a saved course or plan rounds nothing).
_SAME_COURSE_M = 1.0

if TYPE_CHECKING:
    from itt_planner.course.geometry import Course
    from itt_planner.live.engine import PacingEngine
    from itt_planner.model.conditions import Conditions
    from itt_planner.model.rider import Rider
    from itt_planner.ocp.plan import Plan
    from itt_planner.view.ride_report import RideTrace

#: IPOPT's own default for `max_wall_time`: no limit.
NO_WALL_TIME_LIMIT_S = 1e20


@dataclass(frozen=True)
class SessionConfig:
    """What decides the advice of a session (node parameters, replay options).

    Attributes:
        course: course spec for `load_course` (demo name, GPS file, `.course.npz`).
        rider: rider preset name or YAML file.
        model: full-course plan model, "3d" or "1d".
        plan: a saved full-course plan (`Plan.save`); "" to take it from `plan_cache`.
            A plan that keeps the primal-dual point of its NLP (the cache's do:
            `ocp.cache.solve_keeping_point`) makes the first re-solve of the rest of the
            course start warm (`course_replan.plan_point`); one without starts it cold.
        plan_cache: directory of cached full-course plans (solved there when missing).
        horizon_m: receding-horizon length (the planner's `HorizonSettings.horizon_m`).
        replan_period_s: stamp time between two advices.
        on_plan_band_j: W' deviation from the plan within which the advice is the plan
            itself (`EngineSettings`); 0.0 replans every period.
        course_replan_period_s: off the plan, the rest of the course is re-solved at most
            this often (`CourseReplanSettings`); 0.0 never.
        course_resolve_model: what such a re-solve solves (`CourseReplanSettings.model`):
            "auto" (the 3D within 20 km of the finish, the 1D on the plan's line before
            and where the 3D fails),
            "3d", or "1d-line" (the 1D that knows the corners of the plan's line; the 3D
            where its plan is refused): `live.resolve_model`.
        line_gate_m: the horizon plans from the advised line unless GPS puts the rider
            further off it than this (`EngineSettings`).
        diagnostics_period_s: stamp time between two diagnostics messages.
        grip_mu: tyre-road grip, both ways (`Conditions.mu_x`, `mu_y`: 1.0 dry, ~0.6 wet).
        wind_speed_mps: wind speed (`Conditions`).
        wind_from_rad: direction the wind blows from, clockwise from North.
        air_density_kgpm3: air density (the paper's 1.23 by default, at any altitude:
            the session warns when the course's own differs by over 3 %).
        air_temperature_c: the day's air temperature (C); NaN (the default): not
            given. Given, the air density is the course's own: ISA pressure at its mean
            altitude at this temperature (`model.conditions.day_air_density_kgpm3`), and
            `air_density_kgpm3` must be left at its default.
            A plan given by file (`plan`) brings the conditions it was solved in; these
            must then be left at their defaults or agree with it.
        deterministic: no wall-clock values in advice and diagnostics and no wall-time
            caps, so two runs over one log give byte-identical advice (replays); False
            is the live behaviour (overruns judged by the wall clock).
        namespace: ROS namespace of the pacing topics (MCAP topic names).
    """

    course: str = "verona-like"
    rider: str = "paper"
    model: str = "3d"
    plan: str = ""
    plan_cache: str = ".itt_cache"
    horizon_m: float = 1000.0
    replan_period_s: float = 1.0
    on_plan_band_j: float = 2000.0
    course_replan_period_s: float = 30.0
    course_resolve_model: str = "auto"
    line_gate_m: float = 5.0
    diagnostics_period_s: float = 1.0
    grip_mu: float = 1.0
    wind_speed_mps: float = 0.0
    wind_from_rad: float = 0.0
    air_density_kgpm3: float = PAPER_AIR_DENSITY_KGPM3
    air_temperature_c: float = math.nan
    deterministic: bool = False
    namespace: str = DEFAULT_NAMESPACE

    @classmethod
    def from_metadata(cls, values: Mapping[str, str], source: str) -> SessionConfig:
        """The config a session wrote into its log (`RideSession.describe`: strings).

        A field the log does not name keeps its default: a log from before the field
        existed was run with it.

        Raises:
            IttError: a value that is not of its field's type (names `source`).
        """
        kwargs: dict[str, object] = {}
        for f in dataclasses.fields(cls):
            if f.name not in values:
                continue
            text, kind = values[f.name], cast(type[Any], type(f.default))
            try:
                value = {"True": True, "False": False}[text] if kind is bool else kind(text)
            except (KeyError, ValueError):
                raise IttError(f"{source}: session metadata {f.name}={text!r} is not a "
                               f"{kind.__name__}") from None
            # The default's own NaN ("not given"): dataclass equality compares fields as
            # tuples, identity first, so a config read back equals the one written.
            kwargs[f.name] = math.nan if kind is float and math.isnan(value) else value
        return cls(**kwargs)  # type: ignore[arg-type]  # each value of its field's type

    def __post_init__(self) -> None:
        if not math.isnan(self.air_temperature_c) \
                and self.air_density_kgpm3 != PAPER_AIR_DENSITY_KGPM3:
            raise IttError(f"air_density_kgpm3 {self.air_density_kgpm3} and air_temperature_c "
                           f"{self.air_temperature_c}: give one (the temperature sets the "
                           "density at the course's altitude)")

    def conditions(self, mean_altitude_m: float) -> Conditions:
        """The grip, wind and air asked for on a course at `mean_altitude_m` (a plan
        given by file has its own: `session_plan`).

        Raises:
            RiderError: a value out of range (names the field).
        """
        from itt_planner.model.conditions import Conditions, day_air_density_kgpm3  # noqa: PLC0415

        density = (self.air_density_kgpm3 if math.isnan(self.air_temperature_c) else
                   day_air_density_kgpm3(mean_altitude_m, self.air_temperature_c))
        return Conditions(mu_x=self.grip_mu, mu_y=self.grip_mu,
                          wind_speed_mps=self.wind_speed_mps, wind_from_rad=self.wind_from_rad,
                          air_density_kgpm3=density)


def session_plan(config: SessionConfig, course: Course, rider: Rider
                 ) -> tuple[Plan, Conditions]:
    """The full-course plan of a session and the conditions it was solved in: the plan
    file `config.plan` with its own, else the plan cache's (solved there on a miss) in
    the config's. A replay's report takes the same plan as the replay did.

    Raises:
        SolveError: the plan file is of another course, or was solved in other conditions
            than the config asks for (unless those are the defaults).
    """
    # Heavy (CasADi): imported when a plan is actually needed.
    from itt_planner.ocp.cache import load_or_solve  # noqa: PLC0415
    from itt_planner.ocp.course_settings import OcpSettings  # noqa: PLC0415
    from itt_planner.ocp.plan import Plan  # noqa: PLC0415

    conditions = config.conditions(course.mean_altitude_m)
    if config.plan:
        plan = Plan.load(config.plan)
        _check_plan_course(plan, course, config.plan)
        return plan, _plan_conditions(plan, conditions, config.plan)
    return load_or_solve(course, rider, conditions, OcpSettings(), config.model,
                         cache_dir=Path(config.plan_cache)), conditions


def build_engine(config: SessionConfig) -> PacingEngine:
    """Load the course, rider and full-course plan of `config` and build the engine.

    Raises:
        CourseError, RiderError, SolveError: the course, rider or plan is unusable.
    """
    # Heavy (CasADi): imported when a session is actually built.
    from itt_planner.course.loader import load_course  # noqa: PLC0415
    from itt_planner.live.course_replan import CourseReplanSettings  # noqa: PLC0415
    from itt_planner.live.engine import EngineSettings, PacingEngine  # noqa: PLC0415
    from itt_planner.model.rider import load_rider  # noqa: PLC0415
    from itt_planner.ocp.horizon import HorizonPlanner  # noqa: PLC0415
    from itt_planner.ocp.horizon_settings import HorizonSettings  # noqa: PLC0415
    from itt_planner.ocp.solver import PlanStatus  # noqa: PLC0415

    course = load_course(config.course)
    rider = load_rider(config.rider)
    plan, conditions = session_plan(config, course, rider)
    if plan.status in (PlanStatus.FAILED, PlanStatus.INVALID):
        # A capped plan is still a verified trajectory (advised, with a warning); a failed
        # or invalid one is not a plan a rider should be given.
        raise SolveError(f"the full-course plan of {config.course} for {config.rider} is "
                         f"{plan.status} ({plan.solver_status}): not used",
                         status=plan.solver_status)
    horizon = HorizonSettings(horizon_m=config.horizon_m)
    if config.deterministic:
        # IPOPT's wall-time cap would make the result depend on the machine's load; the
        # iteration cap stays the budget.
        horizon = dataclasses.replace(horizon, max_wall_time_s=NO_WALL_TIME_LIMIT_S)
    planner = HorizonPlanner(course, rider, plan, conditions=conditions, settings=horizon)
    settings = EngineSettings(
        replan_period_s=config.replan_period_s,
        on_plan_band_j=config.on_plan_band_j, line_gate_m=config.line_gate_m,
        deterministic=config.deterministic,
        # The horizon covers the rest of the course from its own length from the finish.
        course_replan=CourseReplanSettings(period_s=config.course_replan_period_s,
                                           min_remaining_m=config.horizon_m,
                                           model=config.course_resolve_model))
    return PacingEngine(course, rider, plan, conditions=conditions, planner=planner,
                        settings=settings)


def _check_plan_course(plan: Plan, course: Course, path: str) -> None:
    """Refuse a plan file solved on another course (another file, or the same file
    trimmed, lapped or fitted otherwise): its distances would be read on this course's.

    Raises:
        SolveError: naming the file and both courses.
    """
    sha = plan.meta.get("course_sha256")
    length_m = float(plan.s_m[-1])
    if (sha and course.source_sha256 and sha != course.source_sha256) \
            or abs(length_m - course.length_m) > _SAME_COURSE_M:
        raise SolveError(f"plan {path} was solved on course {plan.meta.get('course', '?')} "
                         f"({length_m:.0f} m), not on {course.name} ({course.length_m:.0f} m)",
                         status="invalid_input")


def _plan_conditions(plan: Plan, asked: Conditions, path: str) -> Conditions:
    """The conditions a plan given by file was solved in: the horizon plans in them (a
    plan solved in a 20 km/h wind was re-planned in still air).

    Raises:
        SolveError: `asked` is not the default and differs from the plan's.
    """
    from itt_planner.model.conditions import Conditions  # noqa: PLC0415

    saved = plan.meta.get("conditions", {})
    own = Conditions(**{f.name: saved[f.name] for f in dataclasses.fields(Conditions)
                        if f.name in saved})
    if asked not in (Conditions(), own):
        raise SolveError(f"plan {path} was solved in {own}, not the session's {asked}: "
                         "leave the session's conditions at their defaults, or solve the "
                         "plan in them", status="invalid_input")
    return own


def ride_setup(trace: RideTrace, course_spec: str | None, rider_spec: str | None,
               cache_dir: Path) -> tuple[Course, Rider, Plan]:
    """The course, rider and full-course plan a replayed ride is compared with.

    Course, rider, model, conditions and plan file default to those the replay's
    metadata names (`SessionConfig.from_metadata`); the plan is the one the replay had
    (`session_plan`: its plan file, else the plan cache's in its conditions, solved
    and stored on a miss).

    Raises:
        IttError: no course or rider given or named, or the ride does not fit the course.
        CourseError, RiderError, SolveError: the course, rider or plan is unusable.
    """
    # Heavy (CasADi): imported when a ride report is actually made.
    from itt_planner.course.loader import load_course  # noqa: PLC0415
    from itt_planner.model.rider import load_rider  # noqa: PLC0415
    logged = SessionConfig.from_metadata(trace.metadata, str(trace.path))
    course_spec = course_spec or trace.metadata.get("course")
    rider_spec = rider_spec or trace.metadata.get("rider")
    if not course_spec or not rider_spec:
        raise IttError(f"{trace.path}: the log's metadata names no course or rider; pass "
                       "--course and --rider")
    course = load_course(course_spec)
    if trace.advice_s_m.max() > course.length_m + 1.0:
        raise IttError(f"{trace.path}: the ride reaches {trace.advice_s_m.max():.0f} m but "
                       f"course {course.name!r} is {course.length_m:.0f} m long: wrong --course?")
    rider = load_rider(rider_spec)
    config = dataclasses.replace(logged, course=course_spec, rider=rider_spec,
                                 plan_cache=str(cache_dir))
    if config.plan and not Path(config.plan).is_file():
        raise IttError(f"{trace.path}: the session was advised from plan {config.plan}, "
                       "which is not here: the report compares the ride with that plan")
    plan, _ = session_plan(config, course, rider)
    return course, rider, plan
