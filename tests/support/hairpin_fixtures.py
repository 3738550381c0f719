"""Fixtures of the closed-loop tests: the hairpin test course and its 3D plan.

Registered for every test by the root conftest (`pytest_plugins`); the plan
is solved once per test run (a file lock keeps the xdist workers from solving it twice)
and cached in pytest's cache directory. It is solved for
`PLAN_CONDITIONS`, the lateral grip the virtual rider uses (`sim.planning_conditions`),
so that in `nominal` the planner's belief equals the simulated truth; planners built in
the tests take the same conditions.
"""

from __future__ import annotations

import pytest
from filelock import FileLock

from itt_planner.course.geometry import Course
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import PRESETS
from itt_planner.ocp.cache import load_or_solve
from itt_planner.ocp.course_settings import OcpSettings
from itt_planner.ocp.plan import Plan
from itt_planner.sim import hairpin_course, planning_conditions

RIDER = PRESETS["paper"]
#: What the planner believes: dry road, still air, the rider's lateral grip.
PLAN_CONDITIONS = planning_conditions(Conditions())


@pytest.fixture(scope="module")
def course() -> Course:
    return hairpin_course()


@pytest.fixture(scope="module")
def plan(course: Course, request: pytest.FixtureRequest) -> Plan:
    cache = request.config.cache.mkdir("itt_plans")
    # One solve per run: the other xdist workers wait for it, then load it.
    with FileLock(cache / "hairpin.lock"):
        return load_or_solve(course, RIDER, PLAN_CONDITIONS, OcpSettings(), "3d",
                             cache_dir=cache)
