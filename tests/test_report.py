"""The static report: HTML with embedded figures, PNG, and the `report` command."""

from __future__ import annotations

import base64
import io
import json
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from synthetic_ride import RIDER, make_course, make_plan
from typer.testing import CliRunner

from itt_planner.cli import app
from itt_planner.course import Course
from itt_planner.errors import IttError
from itt_planner.plan import Plan
from itt_planner.report import render_html, rider_from_plan, summary, write_report


@pytest.fixture(scope="module")
def course() -> Course:
    return make_course()


@pytest.fixture(scope="module")
def plan(course: Course) -> Plan:
    return make_plan(course)


def embedded_images(page: str) -> list[Image.Image]:
    found = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    return [Image.open(io.BytesIO(base64.b64decode(b))) for b in found]


def test_html_is_self_contained_with_overview_and_corner(plan: Plan, course: Course) -> None:
    page = render_html(plan, course, RIDER)
    assert page.startswith("<!DOCTYPE html>") and "http" not in page  # nothing to fetch
    images = embedded_images(page)
    assert len(images) == 1 + len(course.corners)  # overview + the one corner
    for image in images:
        pixels = np.asarray(image.convert("L"), dtype=float)
        assert pixels.std() > 10  # figures, not blank canvases
    assert "critical power w" in page and "440" in page


def test_summary_figures(plan: Plan, course: Course) -> None:
    table = summary(plan, course, RIDER)
    assert table["finish_time_s"] == pytest.approx(plan.finish_time_s, abs=0.01)
    assert table["average_speed_kmh"] == pytest.approx(course.length_m / plan.finish_time_s * 3.6,
                                                       abs=0.01)
    # Time-weighted average power lies between the plan's extremes.
    assert plan.power_w.min() < table["average_power_w"] < plan.power_w.max()
    assert 20 < table["max_lean_deg"] < 45


def test_png_report(plan: Plan, course: Course, tmp_path: Path) -> None:
    out = write_report(plan, course, tmp_path / "r.png", RIDER)
    image = Image.open(out)
    assert image.format == "PNG" and image.height > image.width  # overview above the corner


def test_report_rejects_wrong_course_and_suffix(plan: Plan, course: Course,
                                                tmp_path: Path) -> None:
    short = Course.from_centerline("short", np.linspace(0, 200, 201), np.zeros(201),
                                   np.zeros(201), origin=course.origin)
    with pytest.raises(IttError, match="wrong --course"):
        write_report(plan, short, tmp_path / "r.html")
    with pytest.raises(IttError, match=r"\.html or \.png"):
        write_report(plan, course, tmp_path / "r.pdf")


def test_rider_from_plan_header(plan: Plan) -> None:
    assert rider_from_plan(plan) is None  # the synthetic header names the rider only
    solved = Plan(**{**plan.__dict__, "meta": {"rider": RIDER.__dict__}})
    assert rider_from_plan(solved) == RIDER


def test_cli_report_html_json(plan: Plan, course: Course, tmp_path: Path) -> None:
    plan_path = plan.save(tmp_path / "p.plan.npz")
    course_path = course.save(tmp_path / "c.course.npz")
    out = tmp_path / "report.html"
    result = CliRunner().invoke(app, ["report", str(plan_path), "-o", str(out),
                                      "--course", str(course_path), "--json"])
    assert result.exit_code == 0, result.output
    payload = json.loads(result.stdout)
    assert payload["output"] == str(out) and payload["corners"] == 1
    assert len(embedded_images(out.read_text())) == 2


def test_cli_report_errors(plan: Plan, tmp_path: Path) -> None:
    plan_path = plan.save(tmp_path / "p.plan.npz")
    runner = CliRunner()
    # The plan names course 'synthetic-corner', which no loader knows.
    result = runner.invoke(app, ["report", str(plan_path), "-o", str(tmp_path / "r.html"),
                                 "--json"])
    assert result.exit_code == 1
    assert "synthetic-corner" in json.loads(result.stdout)["error"]
    log = tmp_path / "ride.mcap"
    log.write_bytes(b"")
    result = runner.invoke(app, ["report", str(log), "-o", str(tmp_path / "r.html")])
    assert result.exit_code == 1 and "not supported yet" in result.output


def test_demo_course_named_in_plan_header(tmp_path: Path) -> None:
    """A plan on the verona-like demo: the course is found from the plan's header."""
    from itt_planner.course_loader import load_course  # noqa: PLC0415

    demo = load_course("verona-like")
    plan = make_plan(demo, ds_m=10.0)
    plan = Plan(**{**plan.__dict__, "meta": {"course": "verona-like"}})
    plan_path = plan.save(tmp_path / "v.plan.npz")
    out = tmp_path / "v.png"
    result = CliRunner().invoke(app, ["report", str(plan_path), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "verona-like" in result.stdout and Image.open(out).format == "PNG"
