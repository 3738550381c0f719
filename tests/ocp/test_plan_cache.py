"""Plan cache (`ocp.cache`): a hit returns the stored plan without solving; a change of
the course, rider, conditions, settings, model or plan code misses; a stale or unusable
file is ignored and replaced; only converged and verified plans are stored; a stored plan
keeps the primal-dual point of its own NLP, and a file without one still loads."""

from __future__ import annotations

import ast
import dataclasses
import importlib.util
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from support.courses import straight

from itt_planner.course.geometry import Course
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import PRESETS, Rider
from itt_planner.ocp import cache as plan_cache
from itt_planner.ocp.cache import load_or_solve, plan_key, with_point
from itt_planner.ocp.course_nlp import PrimalDual
from itt_planner.ocp.course_problem import solve_plan, solve_plan_point
from itt_planner.ocp.course_settings import OcpSettings
from itt_planner.ocp.plan import PLAN_ARRAYS, POINT_ARRAYS, Plan

COURSE = straight(600.0)
RIDER = PRESETS["paper"]


@pytest.fixture(scope="module")
def solved() -> Plan:
    """One real 1D solve of the 600 m straight (about a second)."""
    plan = solve_plan(COURSE, RIDER, model="1d")
    assert plan.converged, plan.meta["attempts"]
    return plan


@pytest.fixture
def solver_calls(monkeypatch: pytest.MonkeyPatch, solved: Plan) -> list[tuple[Any, ...]]:
    """Replaces the cache's solver by one that records its inputs and returns `solved`."""
    calls: list[tuple[Any, ...]] = []

    def fake(course: Course, rider: Rider, conditions: Conditions, settings: OcpSettings, *,
             model: str) -> tuple[Plan, None]:
        calls.append((course.name, rider.name, conditions, settings, model))
        return solved, None

    monkeypatch.setattr(plan_cache, "solve_plan_point", fake)
    return calls


def _files(cache_dir: Path) -> list[Path]:
    return sorted(cache_dir.glob("*.plan.npz"))


def test_hit_returns_the_stored_plan_without_solving(
        tmp_path: Path, solved: Plan, solver_calls: list[tuple[Any, ...]]) -> None:
    first = load_or_solve(COURSE, RIDER, model="1d", cache_dir=tmp_path)
    assert len(solver_calls) == 1 and len(_files(tmp_path)) == 1
    again = load_or_solve(COURSE, RIDER, model="1d", cache_dir=tmp_path)
    assert len(solver_calls) == 1  # a hit: no second solve
    for name in PLAN_ARRAYS:  # the file round-trips every array exactly
        np.testing.assert_array_equal(getattr(again, name), getattr(solved, name))
    assert again.status == first.status == "converged"
    assert again.finish_time_s == pytest.approx(solved.finish_time_s, abs=0.0)


@pytest.mark.parametrize("change", [
    lambda: {"course": straight(650.0)},
    lambda: {"rider": PRESETS["climber"]},
    lambda: {"rider": dataclasses.replace(RIDER, critical_power_w=RIDER.critical_power_w + 1)},
    lambda: {"conditions": Conditions(mu_x=0.6, mu_y=0.6)},
    lambda: {"settings": OcpSettings(h_max_1d_m=5.0)},
    lambda: {"model": "3d"},
], ids=["course", "rider", "rider-cp", "conditions", "settings", "model"])
def test_any_input_change_misses(tmp_path: Path, solver_calls: list[tuple[Any, ...]],
                                 change: Callable[[], dict[str, Any]]) -> None:
    base: dict[str, Any] = {"course": COURSE, "rider": RIDER, "conditions": Conditions(),
                            "settings": OcpSettings(), "model": "1d"}
    load_or_solve(cache_dir=tmp_path, **base)
    other = base | change()
    assert plan_key(**other) != plan_key(**base)
    load_or_solve(cache_dir=tmp_path, **other)
    assert len(solver_calls) == 2
    assert len(_files(tmp_path)) == 2


def _solve_modules() -> set[str]:
    """The `itt_planner.model` and `itt_planner.ocp` modules `solve_plan` imports (read
    from the sources, so a module a refactor adds is found)."""
    seen: set[str] = set()
    todo = ["itt_planner.ocp.course_problem"]
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        spec = importlib.util.find_spec(name)
        assert spec is not None and spec.origin is not None, name
        tree = ast.parse(Path(spec.origin).read_text(encoding="utf-8"))
        modules = (node.module or "" for node in ast.walk(tree)
                   if isinstance(node, ast.ImportFrom))
        todo += [m for m in modules if m.startswith(("itt_planner.model.", "itt_planner.ocp."))]
    return seen


def test_plan_code_change_misses(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                 solver_calls: list[tuple[Any, ...]]) -> None:
    """A change of the source of a module that decides a plan (physics, bounds, solver
    options, ...) never reuses a stored plan."""
    args = (COURSE, RIDER, Conditions(), OcpSettings(), "1d")
    key = plan_key(*args)
    assert len(plan_cache.code_hash()) == 16
    # Every model/OCP module the full-course solve imports, directly or not, is hashed.
    assert _solve_modules() <= set(plan_cache.PLAN_CODE_MODULES)
    load_or_solve(*args, cache_dir=tmp_path)
    monkeypatch.setattr(plan_cache, "code_hash", lambda: "another-model")
    assert plan_key(*args) != key
    load_or_solve(*args, cache_dir=tmp_path)
    assert len(solver_calls) == 2


def test_unreadable_file_is_replaced(tmp_path: Path, solved: Plan,
                                     solver_calls: list[tuple[Any, ...]]) -> None:
    """A stale file under the plan's key (truncated by a crash, or garbage) is ignored,
    the plan solved again and the file rewritten whole."""
    load_or_solve(COURSE, RIDER, model="1d", cache_dir=tmp_path)
    (path,) = _files(tmp_path)
    path.write_bytes(b"not a plan")
    got = load_or_solve(COURSE, RIDER, model="1d", cache_dir=tmp_path)
    assert len(solver_calls) == 2 and got is solved
    assert Plan.load(path).finish_time_s == pytest.approx(solved.finish_time_s, abs=0.0)
    assert not list(tmp_path.glob("*.tmp"))  # written through a temporary file


def test_unconverged_file_is_ignored(tmp_path: Path, solved: Plan,
                                     solver_calls: list[tuple[Any, ...]]) -> None:
    """A stored plan that is not converged (written by other code) is never returned."""
    key = plan_key(COURSE, RIDER, Conditions(), OcpSettings(), "1d")
    path = tmp_path / f"{COURSE.name}_1d_{key}.plan.npz"
    dataclasses.replace(solved, status="capped").save(path)
    got = load_or_solve(COURSE, RIDER, model="1d", cache_dir=tmp_path)
    assert len(solver_calls) == 1 and got.converged
    assert Plan.load(path).converged  # replaced by the converged solve


@pytest.mark.parametrize("status", ["invalid", "capped", "failed"])
def test_only_converged_plans_are_stored(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                         solved: Plan, status: str) -> None:
    bad = dataclasses.replace(solved, status=status, meta={**solved.meta, "success": False})
    monkeypatch.setattr(plan_cache, "solve_plan_point", lambda *_a, **_k: (bad, None))
    got = load_or_solve(COURSE, RIDER, model="1d", cache_dir=tmp_path)
    assert got.status == status  # returned, with its status, for the caller to report
    assert not _files(tmp_path)


def test_stored_plan_keeps_its_primal_dual_point(tmp_path: Path) -> None:
    """A real solve through the cache: the stored file holds the point of the plan's own
    NLP (on its nodes), which a hit returns exactly; the same plan saved without it (a
    file from before) loads with none."""
    plan, point = solve_plan_point(COURSE, RIDER, model="1d")
    assert point is not None and plan.converged
    stored = load_or_solve(COURSE, RIDER, model="1d", cache_dir=tmp_path)
    hit = load_or_solve(COURSE, RIDER, model="1d", cache_dir=tmp_path)
    for got in (stored, hit):
        assert got.has_point
        np.testing.assert_array_equal(got.s_m, point.nodes)
        for mine, theirs in ((got.point_w, point.w), (got.point_lam_x, point.lam_x),
                             (got.point_lam_g, point.lam_g)):
            np.testing.assert_array_equal(mine, theirs)  # deterministic solve, exact file
    old = tmp_path / "old.plan.npz"
    dataclasses.replace(hit, point_w=None, point_lam_x=None, point_lam_g=None).save(old)
    with np.load(old) as data:
        assert not set(POINT_ARRAYS) & set(data.files)
    assert not Plan.load(old).has_point
    assert Plan.load(old).point_lam_g is None
    np.testing.assert_array_equal(Plan.load(old).v_mps, hit.v_mps)


def test_a_point_of_other_nodes_is_not_kept(solved: Plan) -> None:
    """Only the point of the plan's own NLP: one on other nodes (another mesh) is dropped."""
    n = 3 * solved.n_nodes
    other = PrimalDual(solved.s_m[:-1], np.zeros(n), np.zeros(n), np.zeros(n))
    assert with_point(solved, other) is solved
    assert with_point(solved, None) is solved
    same = dataclasses.replace(other, nodes=solved.s_m)
    kept = with_point(solved, same)
    assert kept.has_point and kept.point_w is same.w and kept.point_lam_g is same.lam_g
