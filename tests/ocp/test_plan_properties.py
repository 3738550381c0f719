"""Property tests: any course the course builder can make, any plausible rider, gives a
plan with an honest status or a typed error, never a traceback (issue 14 item 1, issue 18).

Courses: straights, arcs (radius 5 m ... 200 m) and clothoids, grades -20 ... +20 %,
0.2 ... ~1.5 km (kept short: this runs the full OCP), some closing into a loop. The 1D
property runs by default; the 3D one is `slow`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from itt_planner.course.builder import build_course
from itt_planner.errors import IttError
from itt_planner.model.rider import Rider
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.solver import PlanStatus

riders = st.builds(
    Rider, mass_kg=st.floats(50, 100), drag_area_m2=st.floats(0.18, 0.45),
    crr=st.floats(0.002, 0.01), critical_power_w=st.floats(150, 500),
    max_lateral_accel_mps2=st.one_of(st.none(), st.floats(3.0, 9.0)))


@st.composite
def segments(draw: st.DrawFn) -> dict[str, Any]:
    grade = draw(st.floats(-20, 20))
    kind = draw(st.sampled_from(["straight", "straight", "arc", "clothoid"]))
    if kind == "straight":
        return {"type": "straight", "length_m": draw(st.floats(50, 500)), "grade_pct": grade}
    radius = draw(st.floats(5, 200))
    direction = draw(st.sampled_from(["left", "right"]))
    if kind == "arc":
        return {"type": "arc", "radius_m": radius, "direction": direction,
                "angle_deg": draw(st.floats(10, 180)), "grade_pct": grade}
    return {"type": "clothoid", "length_m": draw(st.floats(5, 40)), "radius_m": radius,
            "direction": direction, "grade_pct": grade}


@st.composite
def courses(draw: st.DrawFn) -> dict[str, Any]:
    segs = draw(st.lists(segments(), min_size=1, max_size=5))
    if draw(st.booleans()):  # a loop: four 90 deg bends close the lap
        side = draw(st.floats(50, 300))
        radius = draw(st.floats(5, 40))
        segs = [seg for _ in range(4) for seg in (
            {"type": "straight", "length_m": side},
            {"type": "arc", "radius_m": radius, "direction": "left", "angle_deg": 90})]
    total = sum(s.get("length_m", math.radians(s.get("angle_deg", 0)) * s.get("radius_m", 0))
                for s in segs)
    if total < 200:
        segs.append({"type": "straight", "length_m": 200 - total + 1})
    return {"name": "prop", "segments": segs}


def _check(spec: dict[str, Any], rider: Rider, model: str) -> None:
    try:
        course = build_course(spec)
        plan = solve_plan(course, rider, model=model)
    except IttError:
        return  # a typed error with a message is an acceptable outcome
    status = PlanStatus(plan.status)
    assert np.all(np.isfinite(plan.t_s)) or status is not PlanStatus.CONVERGED
    if status is PlanStatus.CONVERGED:
        assert plan.meta["success"] and plan.meta["verification"]["verified"]
        assert np.all(plan.v_mps > 0) and np.all(np.isfinite(plan.v_mps))
        assert plan.finish_time_s > 0
    else:
        assert not plan.meta["success"]


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(spec=courses(), rider=riders)
def test_any_built_course_1d(spec: dict[str, Any], rider: Rider) -> None:
    _check(spec, rider, "1d")


@pytest.mark.slow
@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(spec=courses(), rider=riders)
def test_any_built_course_3d(spec: dict[str, Any], rider: Rider) -> None:
    _check(spec, rider, "3d")
