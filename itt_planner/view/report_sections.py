"""Extra sections of the static report: a title, a table of figures, tables, images.

The report's own content is the plan (or the ride) against distance; later stages add
what they know about it without the view importing them: the calibration stage adds the
calibrated rider (values, uncertainties, sources) and the ride's validation (physics and
plan checks). Each section is plain data, rendered here after the report's figures: as
HTML (`section_html`), or drawn into the PNG report (`draw_section`: the same text, the
tables cut at `PNG_TABLE_ROWS` rows, the images below).
"""

from __future__ import annotations

import base64
import html
import io
import textwrap
from dataclasses import dataclass

import matplotlib.image as mpimg
import numpy as np
from matplotlib.figure import SubFigure

#: A table: its caption and its rows (column -> value), all rows with the same columns.
Table = tuple[str, tuple[dict[str, object], ...]]
#: PNG: characters a text line holds at the figure's width, rows of a table drawn (the
#: HTML has them all), and the height of one text line (inches).
PNG_LINE_CHARS = 160
PNG_TABLE_ROWS = 20
_LINE_IN = 0.12


@dataclass(frozen=True)
class ReportSection:
    """One section: figures by name (`rows`), then `tables`, then images (base64 PNG)."""

    title: str
    rows: dict[str, object]
    tables: tuple[Table, ...] = ()
    images_png_b64: tuple[str, ...] = ()
    note: str = ""


def table_cell(value: object) -> str:
    """A table cell: counts by name as `name: n, ...`, a list as `a; b` (empty: none),
    None as a dash."""
    if isinstance(value, dict):
        return ", ".join(f"{k}: {v}" for k, v in value.items())
    if isinstance(value, list | tuple):
        return "; ".join(str(v) for v in value) or "none"
    return "-" if value is None else str(value)


def section_html(section: ReportSection) -> str:
    """The section as HTML (escaped text, images embedded)."""
    parts = [f"<h2>{html.escape(section.title)}</h2>"]
    if section.note:
        parts.append(f"<p>{html.escape(section.note)}</p>")
    parts.append("<table>" + "".join(
        f"<tr><th>{html.escape(k.replace('_', ' '))}</th><td>{html.escape(table_cell(v))}</td></tr>"
        for k, v in section.rows.items()) + "</table>")
    for caption, rows in section.tables:
        if not rows:
            continue
        head = "".join(f"<th>{html.escape(c.replace('_', ' '))}</th>" for c in rows[0])
        body = "".join("<tr>" + "".join(f"<td>{html.escape(table_cell(v))}</td>"
                                        for v in row.values()) + "</tr>" for row in rows)
        parts.append(f"<h3>{html.escape(caption)}</h3><table class='grid'><tr>{head}</tr>"
                     f"{body}</table>")
    parts += [f'<p><img alt="{html.escape(section.title)} figure {i}" '
              f'src="data:image/png;base64,{png}"></p>'
              for i, png in enumerate(section.images_png_b64)]
    return "".join(parts)


def section_lines(section: ReportSection) -> list[str]:
    """The section's text for the PNG: the note, each figure by name, each table (cut at
    `PNG_TABLE_ROWS` rows, saying how many more the HTML report has)."""
    lines = [section.title.upper()]
    if section.note:
        lines += textwrap.wrap(section.note, PNG_LINE_CHARS)
    for k, v in section.rows.items():
        lines += textwrap.wrap(f"{k.replace('_', ' ')}: {table_cell(v)}", PNG_LINE_CHARS,
                               subsequent_indent="    ")
    for caption, rows in section.tables:
        if not rows:
            continue
        cells = [[c.replace("_", " ") for c in rows[0]]]
        cells += [[table_cell(v) for v in row.values()] for row in rows[:PNG_TABLE_ROWS]]
        widths = [max(len(r[i]) for r in cells) for i in range(len(cells[0]))]
        lines += ["", f"{caption}:"]
        lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True))[:PNG_LINE_CHARS]
                  for r in cells]
        if len(rows) > PNG_TABLE_ROWS:
            lines.append(f"... {len(rows) - PNG_TABLE_ROWS} more rows in the HTML report")
    return lines


def _images(section: ReportSection) -> list[np.ndarray]:
    return [np.asarray(mpimg.imread(io.BytesIO(base64.b64decode(png)), format="png"))
            for png in section.images_png_b64]


def section_height_in(section: ReportSection, width_in: float) -> float:
    """Height (inches) `draw_section` needs at `width_in`."""
    text = _LINE_IN * (len(section_lines(section)) + 1)
    return text + float(sum(width_in * img.shape[0] / img.shape[1] for img in _images(section)))


def draw_section(fig: SubFigure, section: ReportSection, width_in: float) -> None:
    """The section into `fig` (`section_height_in` tall): its text, then its images."""
    images = _images(section)
    text_in = _LINE_IN * (len(section_lines(section)) + 1)
    heights = [text_in] + [width_in * img.shape[0] / img.shape[1] for img in images]
    subs = fig.subfigures(len(heights), 1, squeeze=False, height_ratios=heights)[:, 0]
    ax = subs[0].add_axes((0.0, 0.0, 1.0, 1.0))
    ax.axis("off")
    ax.text(0.01, 1.0, "\n".join(section_lines(section)), va="top", ha="left",
            family="monospace", fontsize=7, transform=ax.transAxes)
    for sub, img in zip(subs[1:], images, strict=True):
        axi = sub.add_axes((0.0, 0.0, 1.0, 1.0))
        axi.imshow(img)
        axi.axis("off")
