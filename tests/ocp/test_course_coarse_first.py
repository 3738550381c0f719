"""A cold 3D full-course solve on a large mesh starts on every other node, then resumes
on the full mesh (`course_restarts`, "coarse mesh first"): the same plan as a cold start
on the full mesh, and only for cold 3D solves above the node threshold."""

from __future__ import annotations

import numpy as np
import pytest
from support.courses import SHORT

from itt_planner.course.builder import build_course
from itt_planner.model.rider import PRESETS
from itt_planner.ocp import course_restarts
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.solver import PlanStatus


def test_coarse_mesh_first_reaches_the_cold_plan(monkeypatch: pytest.MonkeyPatch) -> None:
    course, rider = build_course(SHORT), PRESETS["paper"]
    cold = solve_plan(course, rider, model="3d")
    assert [a["strategy"] for a in cold.meta["attempts"]] == ["cold"]  # below the threshold
    assert cold.meta["success"], cold.solver_status
    monkeypatch.setattr(course_restarts, "_COARSE_MIN_NODES", 0)
    plan = solve_plan(course, rider, model="3d")
    assert plan.meta["success"], plan.meta["attempts"]
    coarse, fine = plan.meta["attempts"][:2]
    assert coarse["strategy"] == "coarse mesh" and coarse["outcome"] == PlanStatus.CONVERGED
    assert fine["strategy"] == "from the coarse mesh"
    # Every other node of the full mesh, and its last.
    assert coarse["n_nodes"] == (plan.n_nodes + 2) // 2
    assert np.array_equal(plan.s_m, cold.s_m)
    assert plan.finish_time_s == pytest.approx(cold.finish_time_s, rel=5e-4)
    # The 1D model and a solve from a given plan never take the coarse mesh first.
    one = solve_plan(course, rider, model="1d")
    assert "coarse mesh" not in [a["strategy"] for a in one.meta["attempts"]]
    warm = solve_plan(course, rider, model="3d", guess=cold)
    assert warm.meta["attempts"][0]["strategy"] == "guess"
