"""A long cold 3D solve goes through overlapping windows and a polish of their stitched
point (`course_windows`, `course_restarts` "windows first"); a 1D run that did not
converge restarts with the never-monotone barrier. The thresholds are settings (or
module constants) passed small here, so that a 1.2 km course exercises them."""

from __future__ import annotations

import dataclasses
import itertools
from typing import Any

import numpy as np
import pytest
from support.courses import SHORT
from support.real_data import data_path

from itt_planner.course.builder import build_course
from itt_planner.course.loader import load_course
from itt_planner.model.rider import PRESETS
from itt_planner.ocp import course_budget, course_restarts
from itt_planner.ocp.course_budget import Budget
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.course_settings import OcpSettings
from itt_planner.ocp.course_windows import (
    plan_windows,
    stitch,
    window_corners_per_km,
    window_iter_cap,
)
from itt_planner.ocp.solver import PlanStatus, SolveResult, full_course_solver
from itt_planner.ocp.transcription import Layout


def test_windows_cover_the_course_with_overlaps() -> None:
    nodes = np.cumsum(np.r_[0.0, np.full(300, 4.0), np.full(400, 1.0)])  # 1,600 m
    wins = plan_windows(nodes, 500.0, 120.0)
    assert len(wins) == 4
    assert wins[0].first == 0 and wins[-1].core_end == wins[-1].last == len(nodes) - 1
    for a, b in itertools.pairwise(wins):
        assert b.first == a.core_end  # the cores tile the mesh
        assert nodes[a.last] - nodes[a.core_end] >= 120.0 - 4.0  # the overlap
    assert plan_windows(nodes, 5000.0, 120.0)[0].last == len(nodes) - 1  # one window


def test_windows_are_shorter_where_the_corners_are() -> None:
    """A window holds `window_m` of work, a corner counting `corner_m` metres: a 2 km
    stretch of 20 corners gets the short windows, the open road the long ones, and no
    cut lands within 250 m of an apex (or off the middle of a shorter gap)."""
    nodes = np.arange(0.0, 10_000.0 + 1.0, 4.0)
    apex = np.r_[np.linspace(4_050.0, 5_950.0, 20), 8_000.0]
    wins = plan_windows(nodes, 2_500.0, 300.0, apex, 150.0)
    assert len(wins) == 6  # (10 km + 21 x 150 m) / 2.5 km
    cores = [(nodes[w.first], nodes[w.core_end]) for w in wins]
    city = [b - a for a, b in cores if 4_000.0 <= 0.5 * (a + b) <= 6_000.0]
    road = [b - a for a, b in cores if 0.5 * (a + b) < 3_500.0]
    assert city and road and max(city) < 0.8 * min(road)
    gaps = np.diff(apex).min()
    for w in wins[1:]:
        cut = nodes[w.first]
        clear = np.abs(apex - cut).min()
        assert clear >= min(250.0, 0.5 * gaps) - 4.0, (cut, clear)
    assert wins[0].first == 0 and wins[-1].core_end == len(nodes) - 1
    for a, b in itertools.pairwise(wins):
        assert b.first == a.core_end
    assert window_corners_per_km(nodes[: 1501], apex) == pytest.approx(20 / 6.0)
    # No corners: the equal cores by length.
    assert plan_windows(nodes, 2_500.0, 300.0, np.array([]), 150.0) == plan_windows(
        nodes, 2_500.0, 300.0)


def _window_of(layout: Layout, v: np.ndarray, g: np.ndarray, first: int, last: int
               ) -> SolveResult:
    """The slice of a full-course point a window on nodes first..last would hold."""
    lay = Layout(layout.nx, layout.nu, 0, last - first, layout.n_path, layout.accel)

    def part(vec: np.ndarray) -> np.ndarray:
        x, u, _ = layout.split(vec)
        return lay.join(x[:, first: last + 1], u[:, first: last])

    gaps = g[: layout.n_gap].reshape(layout.n_intervals, layout.nx)[first:last]
    path = g[layout.n_gap: layout.n_gap + layout.n_path * layout.n_nodes].reshape(
        layout.n_nodes, layout.n_path)[first: last + 1]
    accel = g[layout.accel_rows][first:last]
    lam_g = np.concatenate([gaps.ravel(), path.ravel(), accel])
    return SolveResult(part(v), part(v + 1.0), lam_g, 0.0, PlanStatus.CONVERGED, "ok", 1, 0.0)


def test_stitching_the_slices_of_a_point_gives_the_point_back() -> None:
    layout = Layout(nx=8, nu=2, ns=0, n_intervals=60, n_path=3)
    rng = np.random.default_rng(0)
    w, lam_g = rng.normal(size=layout.n_var), rng.normal(size=layout.n_g)
    nodes = np.linspace(0.0, 600.0, layout.n_nodes)
    wins = plan_windows(nodes, 250.0, 60.0)
    runs = []
    for k, win in enumerate(wins):
        run = _window_of(layout, w, lam_g, win.first, win.last)
        if k:  # a window's first node is its fixed start: the stitch must not take it
            assert run.lam_x is not None
            run.lam_x[: layout.nx] = np.nan
        runs.append(run)
    point = stitch(layout, wins, runs)
    assert np.array_equal(point.w, w)
    assert point.lam_x is not None
    assert np.array_equal(point.lam_x, w + 1.0)
    assert point.lam_g is not None
    assert np.array_equal(point.lam_g, lam_g)


def test_windows_first_reaches_the_cold_plan() -> None:
    course, rider = build_course(SHORT), PRESETS["paper"]
    cold = solve_plan(course, rider, model="3d")
    assert cold.meta["success"], cold.meta["attempts"]
    assert "1d plan for the windows" not in [a["strategy"] for a in cold.meta["attempts"]]
    settings = OcpSettings(window_min_m=0.0, window_m=700.0, window_overlap_m=300.0)
    plan = solve_plan(course, rider, settings=settings, model="3d")
    assert plan.meta["success"], plan.meta["attempts"]
    strategies = [a["strategy"] for a in plan.meta["attempts"]]
    assert strategies[0] == "1d plan for the windows"
    assert strategies[1].startswith("window 1/2") and strategies[-1] == "polish from the windows"
    assert np.array_equal(plan.s_m, cold.s_m)
    assert plan.finish_time_s == pytest.approx(cold.finish_time_s, rel=5e-4)
    # Windows among dense corners start from the default (arc) guess: the same plan.
    arc = solve_plan(course, rider, model="3d", settings=dataclasses.replace(
        settings, window_arc_guess_corners_per_km=-1.0))
    assert arc.meta["success"], arc.meta["attempts"]
    assert "arc guess" in arc.meta["attempts"][1]["strategy"]
    assert arc.finish_time_s == pytest.approx(cold.finish_time_s, rel=5e-4)
    # A start mid-course or a given guess never takes the windows.
    warm = solve_plan(course, rider, settings=settings, model="3d", guess=cold)
    assert warm.meta["attempts"][0]["strategy"] == "guess"


def test_a_window_at_its_iteration_cap_starts_again_with_the_smaller_bound_push() -> None:
    course, rider = build_course(SHORT), PRESETS["paper"]
    settings = OcpSettings(window_min_m=0.0, window_m=700.0, window_overlap_m=300.0,
                           window_max_iter=5)
    plan = solve_plan(course, rider, settings=settings, model="3d")
    attempts = plan.meta["attempts"]
    first, retry = attempts[1], attempts[2]
    assert first["strategy"].startswith("window 1/2") and first["iterations"] == 5
    assert first["outcome"] == PlanStatus.CAPPED
    assert retry["strategy"] == first["strategy"] + ", smaller bound push"
    assert retry["iterations"] > 5  # the retry is not held to the cap
    assert plan.meta["success"], attempts


def test_windows_from_the_1d_plan_cap_the_barrier_and_the_polish_has_its_tolerance(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """`OcpSettings.window_mu_max` on every run of a window from the 1D plan (not from
    the arc guess, not the polish), `window_polish_tol` on the polish alone; the 1D plan
    the windows start from with the never-monotone barrier, no 3D run."""
    calls: list[tuple[str, dict[str, Any]]] = []
    real = full_course_solver

    def spy(tr: Any, **kwargs: Any) -> Any:
        calls.append((tr.model.name, kwargs))
        return real(tr, **kwargs)

    monkeypatch.setattr(course_budget, "full_course_solver", spy)
    course, rider = build_course(SHORT), PRESETS["paper"]
    settings = OcpSettings(window_min_m=0.0, window_m=700.0, window_overlap_m=300.0,
                           window_mu_max=0.05, window_polish_tol=3e-6)
    for arc_per_km, mu_max in ((1e9, 0.05), (-1.0, None)):  # from the 1D plan / arc guess
        calls.clear()
        plan = solve_plan(course, rider, model="3d", settings=dataclasses.replace(
            settings, window_arc_guess_corners_per_km=arc_per_km))
        assert plan.meta["success"], plan.meta["attempts"]
        *windows, polish = [kw for name, kw in calls if name == "3d"]
        assert len(windows) >= 2
        assert all(kw["mu_max"] == mu_max and kw["tol"] == settings.tol for kw in windows)
        assert polish["resume"] and polish["mu_max"] is None and polish["tol"] == 3e-6
        assert all(kw["mu_max"] is None for name, kw in calls if name == "1d")
        assert all(kw["never_monotone"] == (name == "1d") for name, kw in calls)


def test_a_window_may_run_half_again_the_iterations_of_the_slowest_one_before_it() -> None:
    settings = OcpSettings()  # 600 at most, 200 at least, 1.5x the slowest before
    assert window_iter_cap(settings, []) == 600  # the first window: nothing to go by
    assert window_iter_cap(settings, [37, 77, 54]) == 200  # Shanghai's window 5
    assert window_iter_cap(settings, [132, 129, 91, 170, 116]) == 255  # Sauerland's 9th
    assert window_iter_cap(settings, [248, 103, 154, 86]) == 372  # Ardennes's 5th: 338
    assert window_iter_cap(settings, [338, 248, 154]) == 507
    assert window_iter_cap(settings, [450]) == 600


def test_a_window_that_fails_from_the_1d_plan_goes_on_from_the_arc_guess(
        monkeypatch: pytest.MonkeyPatch) -> None:
    course, rider = build_course(SHORT), PRESETS["paper"]
    settings = OcpSettings(window_min_m=0.0, window_m=700.0, window_overlap_m=300.0,
                           window_arc_guess_corners_per_km=1e9)  # every window from the 1D
    real_run = Budget.run

    def run(self: Budget, strategy: str, *args: Any, **kwargs: Any) -> Any:
        if strategy.startswith("window 1/2") and "arc guess" not in strategy:
            kwargs["max_iter"] = 2  # every run of the first window from the 1D plan fails
        return real_run(self, strategy, *args, **kwargs)

    monkeypatch.setattr(Budget, "run", run)
    plan = solve_plan(course, rider, settings=settings, model="3d")
    first = [a for a in plan.meta["attempts"] if a["strategy"].startswith("window 1/2")]
    assert [a["outcome"] for a in first[:-1]] == [PlanStatus.CAPPED] * (len(first) - 1)
    assert first[-1]["strategy"].endswith(", arc guess)")
    assert first[-1]["outcome"] == PlanStatus.CONVERGED
    assert plan.meta["attempts"][-1]["strategy"] == "polish from the windows"
    assert plan.meta["success"], plan.meta["attempts"]


def test_a_capped_1d_run_restarts_with_the_never_monotone_barrier(
        monkeypatch: pytest.MonkeyPatch) -> None:
    course, rider = build_course(SHORT), PRESETS["paper"]
    monkeypatch.setattr(course_restarts, "_FIRST_SHARE", 0.01)  # the first run is capped
    plan = solve_plan(course, rider, model="1d")
    first, second = plan.meta["attempts"][:2]
    assert first["outcome"] == PlanStatus.CAPPED
    assert second["strategy"] == "never-monotone barrier"
    assert plan.meta["success"], plan.meta["attempts"]


@pytest.mark.slow
def test_the_80_km_stop_go_ride_converges_through_the_windows() -> None:
    """The Shanghai ride (80 km, 245 corners): capped after 571 iterations without the
    windows (bench/RESULTS.md, 2026-12-02); ~15-30 min of CPU on a shared machine."""
    course = load_course(data_path("rides/elemnt_shanghai_2019_stopgo.fit"))
    plan = solve_plan(course, PRESETS["typical"], model="3d")
    strategies = [a["strategy"] for a in plan.meta["attempts"]]
    assert strategies[0] == "1d plan for the windows"
    assert plan.meta["success"], plan.meta["attempts"]
