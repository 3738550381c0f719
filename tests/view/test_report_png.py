"""The PNG report draws the extra sections (calibrated rider, validation) as the HTML has
them: their text, their tables cut to a readable length, and their images."""

from __future__ import annotations

import base64
import io

import matplotlib.image as mpimg
import numpy as np
from matplotlib.figure import Figure
from support.synthetic_ride import make_course, make_plan

from itt_planner.view.report import png_bytes, render_png
from itt_planner.view.report_sections import PNG_TABLE_ROWS, ReportSection, section_lines


def _png_b64(height_in: float) -> str:
    fig = Figure(figsize=(8.0, height_in))
    fig.add_subplot().plot([0, 1], [0, 1])
    return base64.b64encode(png_bytes(fig, 50)).decode()


def _shape(png: bytes) -> tuple[int, int]:
    img = np.asarray(mpimg.imread(io.BytesIO(png), format="png"))
    return int(img.shape[0]), int(img.shape[1])


def test_png_report_has_the_sections() -> None:
    """A section with a 30-row table and a figure makes the PNG taller by its text and its
    figure; the table is cut at `PNG_TABLE_ROWS` rows, saying how many more the HTML has."""
    course = make_course()
    plan = make_plan(course)
    rows: tuple[dict[str, object], ...] = tuple({"km": k, "mae_kmh": 1.5 + 0.01 * k}
                                                for k in range(30))
    section = ReportSection("Validation against the ride",
                            {"physics 1d (day wind)": "finish 100 s vs 99 s (+1.01 %)"},
                            (("per km", rows),), (_png_b64(3.0),), note="A note.")
    lines = section_lines(section)
    assert lines[0] == "VALIDATION AGAINST THE RIDE" and "A note." in lines
    assert any(line.startswith("physics 1d (day wind): finish") for line in lines)
    assert sum(line.split(" ")[0].isdigit() for line in lines) == PNG_TABLE_ROWS
    assert lines[-1] == f"... {30 - PNG_TABLE_ROWS} more rows in the HTML report"
    bare = _shape(render_png(plan, course))
    full = _shape(render_png(plan, course, sections=(section,)))
    assert full[1] == bare[1]
    # The figure alone is 11 in wide x 3/8 of it tall at the report's 110 dpi or so.
    assert full[0] - bare[0] > 0.9 * (11.0 * 3.0 / 8.0) * bare[1] / 11.0
