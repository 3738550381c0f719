"""Every real course and ride, end to end through the CLI: never a traceback.

Each step ends in a result (exit 0) or a typed error: exit 1 and exactly one JSON object
with the error's type and a message naming the problem. The corpus is every file of
`real_data` (the MIT rides in tests/data, the unlicensed ones beside the checkout, which
skip when absent).

Default suite (cheap): the whole course of every file (trimmed, altitude checked), and a
1D plan of its first 2 km. `slow`: course -> 1D and 3D plan -> simulate -> import ->
replay -> report on the whole course; the plans must converge (exit 0).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from support.real_data import COURSES, RIDES, data_path
from typer.testing import CliRunner

from itt_planner.cli import app
from itt_planner.course.geometry import Course

CORPUS = COURSES + RIDES
runner = CliRunner()


def run(*args: str) -> dict[str, Any]:
    """Invoke the CLI with --json; return its one JSON object, asserting the contract."""
    result = runner.invoke(app, [*args, "--json"])
    assert result.exception is None or isinstance(result.exception, SystemExit), (
        f"{args[0]}: raised {type(result.exception).__name__}: {result.exception}")
    assert "Traceback" not in result.output
    data = json.loads(result.stdout)
    assert isinstance(data, dict)
    if result.exit_code != 0:
        assert result.exit_code == 1 and {"type", "error"} <= set(data), (args, data)
        assert data["type"].endswith("Error") and len(data["error"]) > 10, data
    data["_exit"] = result.exit_code
    return data


@pytest.mark.parametrize("rel", CORPUS)
def test_course_and_short_1d_plan(rel: str, real_course: Callable[[str], Course],
                                  tmp_path: Path) -> None:
    """Every real file: the whole course (fitted once per run for every test that needs
    it), its arrays and its `course info`; through the CLI, its first 2 km fitted and a
    converged 1D plan on them (the CLI's fit of the whole file: `test_full_pipeline`)."""
    src = data_path(rel)
    course = real_course(rel)
    full = course.save(tmp_path / "full.course.npz")
    assert np.all(np.abs(np.tan(course.beta_rad)) <= 0.25)
    assert np.all(np.isfinite(course.kappa_per_m))
    assert np.all(np.diff(course.s_m) > 0)
    info = run("course", "info", str(full))
    assert info["_exit"] == 0, info
    assert info["length_m"] > 10_000 and info["n_corners"] == len(info["corners"])
    assert info["min_grade"] >= -0.25 and info["max_grade"] <= 0.25
    # No turn a bike cannot ride (real hairpins turn ~180 deg, so the angle says nothing):
    # a ride that leaves and returns along the same road, or circles at the finish, must
    # not be closed into a loop with a U-turn at the seam.
    assert all(c["min_radius_m"] > 5.0 for c in info["corners"]), info["corners"]
    assert {"trim", "elevation", "road_width"} <= set(info["build"])
    piece = tmp_path / "piece.course.npz"
    saved = run("course", "save", str(src), "--finish", "2km", "-o", str(piece))
    # Distance along the fixes vs along the fitted line: within a few % (sparse CSV points).
    assert saved["_exit"] == 0 and 1_850 < saved["length_m"] < 2_150, saved
    plan = run("plan", "--course", str(piece), "--rider", "typical", "--model", "1d",
               "-o", str(tmp_path / "p.plan.npz"))
    assert plan["_exit"] == 0, plan  # a converged 1D plan on 2 km of real road


@pytest.mark.slow
@pytest.mark.parametrize("rel", CORPUS)
def test_full_pipeline(rel: str, tmp_path: Path) -> None:
    src = data_path(rel)
    course = tmp_path / "c.course.npz"
    assert run("course", "save", str(src), "-o", str(course))["_exit"] == 0
    assert np.isfinite(Course.load(course).beta_rad).all()
    for model in ("1d", "3d"):
        plan = run("plan", "--course", str(course), "--rider", "typical", "--model", model,
                   "-o", str(tmp_path / f"{model}.plan.npz"))
        assert plan["_exit"] == 0, (model, plan)  # converged, or the CLI says it did not
    sim = run("simulate", "--course", str(course), "--rider", "typical")
    assert sim["_exit"] == 0, sim
    report = run("report", str(tmp_path / "3d.plan.npz"), "-o", str(tmp_path / "plan.html"))
    assert report["_exit"] == 0, report
    if rel.startswith("rides/"):
        log = tmp_path / "ride.mcap"
        assert run("import", str(src), "-o", str(log))["_exit"] == 0
        replay = run("replay", str(log), "--course", str(course), "--rider", "typical",
                     "--out", str(tmp_path / "advice.mcap"))
        assert replay["_exit"] in (0, 1), replay  # 1: damaged input, reported in errors
        report = run("report", str(tmp_path / "advice.mcap"), "-o", str(tmp_path / "r.html"))
        assert report["_exit"] == 0, report
