"""Fixtures of the closed-loop tests: the hairpin test course and its 3D plan.

Import them into a test module (`from hairpin_fixtures import course, plan`); the plan
is solved once per test run and cached in pytest's cache directory.
"""

from __future__ import annotations

import pytest

from itt_planner.conditions import Conditions
from itt_planner.ocp import OcpSettings
from itt_planner.plan_cache import load_or_solve
from itt_planner.rider import PRESETS
from itt_planner.simulate import hairpin_course

RIDER = PRESETS["paper"]


@pytest.fixture(scope="module")
def course():
    return hairpin_course()


@pytest.fixture(scope="module")
def plan(course, request):
    return load_or_solve(course, RIDER, Conditions(), OcpSettings(), "3d",
                         cache_dir=request.config.cache.mkdir("itt_plans"))
