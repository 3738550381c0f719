"""Extra sections of the static report (HTML): a title, a table of figures, tables, images.

The report's own content is the plan (or the ride) against distance; later stages add
what they know about it without the view importing them: the calibration stage adds the
calibrated rider (values, uncertainties, sources) and the ride's validation (physics and
plan checks). Each section is plain data, rendered here after the report's figures.
"""

from __future__ import annotations

import html
from dataclasses import dataclass

#: A table: its caption and its rows (column -> value), all rows with the same columns.
Table = tuple[str, tuple[dict[str, object], ...]]


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
