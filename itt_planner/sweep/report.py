"""The sweep report a directeur sportif reads: one static HTML page with embedded PNG figures.

From a result dataset (`store.ResultStore`), converged cases only (the others are counted
and listed with their reasons):

1. finish time against wind: per course and rider, a heatmap over wind direction x speed
   of the time lost or gained against the calmest wind (dry, reference equipment, 3D);
2. the cost of the wet: each rider's finish on each lower grip minus the driest, 1D and
   3D side by side (the 1D model has no corners, so it hardly sees the wet);
3. each rider's gain from each equipment choice against the reference choice (the first
   in the spec; "stock" if there is one), 1D and 3D;
4. 3D minus 1D finish time per rider, on each grip.

Differences are taken case by case (the same course, rider, wind, grip, W' model and
equipment apart from the axis compared) and summarised by the median over the other
axes, with the range as whiskers. HTML and PNG embedding as in `itt_planner.view.report`.
"""

from __future__ import annotations

import base64
import html
import math
import statistics
from collections import Counter, defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import matplotlib as mpl
import numpy as np
from matplotlib.figure import Figure

from itt_planner.errors import IttError
from itt_planner.sweep.solve import CONVERGED
from itt_planner.sweep.store import ResultStore
from itt_planner.units import MPS_TO_KMH
from itt_planner.view.report import DPI, png_bytes
from itt_planner.view.report_sections import table_cell

#: The inputs that identify a case apart from its labels (course, rider).
_AXES = ("course", "rider", "model", "wind_speed_mps", "wind_from_rad", "mu", "wprime_model",
         "equipment")
_MODEL_COLOURS = {"1d": "tab:gray", "3d": "tab:blue"}
#: Failed cases listed by name in the report's table.
_MAX_LISTED = 20


def _key(row: dict[str, Any], **replace: Any) -> tuple[Any, ...]:
    return tuple(replace.get(a, row[a]) for a in _AXES)


def _reference_equipment(rows: list[dict[str, Any]]) -> str:
    names = sorted({r["equipment"] for r in rows})
    return "stock" if "stock" in names else names[0]


def _differences(rows: list[dict[str, Any]], axis: str, reference: Any,
                 sign: float = 1.0) -> dict[tuple[str, str, Any], list[float]]:
    """(rider, model, value of `axis`) -> [finish(value) - finish(reference)] * sign, over
    every case whose twin at the reference exists."""
    finish = {_key(r): r["finish_time_s"] for r in rows}
    out: dict[tuple[str, str, Any], list[float]] = defaultdict(list)
    for r in rows:
        if r[axis] == reference:
            continue
        base = finish.get(_key(r, **{axis: reference}))
        if base is not None:
            out[(r["rider"], r["model"], r[axis])].append(sign * (r["finish_time_s"] - base))
    return out


def _bars(fig: Figure, diffs: dict[tuple[str, str, Any], list[float]], label: Callable[[Any], str],
          ylabel: str, title: str) -> None:
    """Grouped bars: riders on x, one bar per (value, model), median with range whiskers."""
    ax = fig.subplots()
    riders = sorted({k[0] for k in diffs})
    series = sorted({(k[2], k[1]) for k in diffs}, key=lambda s: (str(s[0]), s[1]))
    width = 0.8 / max(len(series), 1)
    for j, (value, model) in enumerate(series):
        med, lo, hi = [], [], []
        for rider in riders:
            vals = diffs.get((rider, model, value), [])
            m = statistics.median(vals) if vals else math.nan
            med.append(m)
            lo.append(m - min(vals) if vals else 0.0)
            hi.append(max(vals) - m if vals else 0.0)
        x = np.arange(len(riders)) + (j - (len(series) - 1) / 2) * width
        ax.bar(x, med, width, yerr=[lo, hi], capsize=3, label=f"{label(value)}, {model.upper()}",
               color=_MODEL_COLOURS.get(model), alpha=0.55 + 0.45 * (j % 2 == 0),
               edgecolor="black", lw=0.5)
    ax.axhline(0.0, color="black", lw=0.8)
    ax.set_xticks(np.arange(len(riders)), riders)
    ax.set_ylabel(ylabel)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize="small")
    fig.suptitle(title)


def _wind_figure(rows: list[dict[str, Any]], course: str) -> Figure | None:
    """Heatmaps per rider: finish time minus the calmest wind's, direction x speed."""
    sel = [r for r in rows if r["course"] == course]
    model = "3d" if any(r["model"] == "3d" for r in sel) else sel[0]["model"]
    dry = max(r["mu"] for r in sel)
    equip = _reference_equipment(sel)
    wprime = min({r["wprime_model"] for r in sel})
    sel = [r for r in sel if r["model"] == model and r["mu"] == dry and r["equipment"] == equip
           and r["wprime_model"] == wprime]
    speeds = sorted({r["wind_speed_mps"] for r in sel})
    directions = sorted({r["wind_from_rad"] for r in sel})
    if len(speeds) * len(directions) < 2:
        return None
    riders = sorted({r["rider"] for r in sel})
    fig = Figure(figsize=(min(4.2 * len(riders) + 1, 16), 3.8))
    axes = np.atleast_1d(fig.subplots(1, len(riders), squeeze=False)[0])
    for ax, rider in zip(axes, riders, strict=True):
        grid = np.full((len(speeds), len(directions)), math.nan)
        for r in sel:
            if r["rider"] == rider:
                grid[speeds.index(r["wind_speed_mps"]), directions.index(r["wind_from_rad"])] = \
                    r["finish_time_s"]
        calm = np.nanmin(grid[0]) if np.any(np.isfinite(grid[0])) else math.nan
        delta = grid - calm
        lim = max(float(np.nanmax(np.abs(delta))) if np.any(np.isfinite(delta)) else 1.0, 0.1)
        im = ax.imshow(delta, cmap="RdBu_r", vmin=-lim, vmax=lim, aspect="auto", origin="lower")
        for (i, j), v in np.ndenumerate(delta):
            if math.isfinite(v):
                ax.text(j, i, f"{v:+.1f}", ha="center", va="center", fontsize="small")
        ax.set_xticks(range(len(directions)), [f"{math.degrees(d):.0f}" for d in directions])
        ax.set_yticks(range(len(speeds)), [f"{s * MPS_TO_KMH:.0f}" for s in speeds])
        ax.set_xlabel("wind from (deg, 0 = North)")
        ax.set_ylabel("wind (km/h)")
        ax.set_title(f"{rider}: calm {calm:.1f} s", fontsize="medium")
        fig.colorbar(im, ax=ax, label="finish - calm (s)", shrink=0.85)
    fig.suptitle(f"{Path(course).name}: finish time against wind ({model.upper()}, grip "
                 f"{dry:g}, {equip})")
    return fig


def _figures(rows: list[dict[str, Any]]) -> list[Figure]:
    figs = [f for c in sorted({r["course"] for r in rows}) if (f := _wind_figure(rows, c))]
    dry = max(r["mu"] for r in rows)
    wet = _differences(rows, "mu", dry)
    if wet:
        figs.append(Figure(figsize=(11, 4.2)))
        _bars(figs[-1], wet, lambda mu: f"grip {mu:g}", "finish - dry (s)",
              f"The cost of the wet: finish time on lower grip minus grip {dry:g}")
    ref = _reference_equipment(rows)
    gains = _differences(rows, "equipment", ref, sign=-1.0)
    if gains:
        figs.append(Figure(figsize=(11, 4.2)))
        _bars(figs[-1], gains, str, f"time saved vs {ref} (s)",
              f"Each rider's gain from each equipment choice (against {ref})")
    if {"1d", "3d"} <= {r["model"] for r in rows}:
        figs.append(Figure(figsize=(11, 4.2)))
        _bars(figs[-1], _model_gap(rows), lambda mu: f"grip {mu:g}", "3D - 1D finish (s)",
              "What the 3D model adds: corners, lean and the line (3D minus 1D finish)")
    return figs


def _model_gap(rows: list[dict[str, Any]]) -> dict[tuple[str, str, Any], list[float]]:
    """(rider, "3d", grip) -> [3D finish - 1D finish] over the cases solved with both."""
    finish = {_key(r): r["finish_time_s"] for r in rows}
    out: dict[tuple[str, str, Any], list[float]] = defaultdict(list)
    for r in rows:
        if r["model"] == "3d":
            base = finish.get(_key(r, model="1d"))
            if base is not None:
                out[(r["rider"], "3d", r["mu"])].append(r["finish_time_s"] - base)
    return out


def summary(all_rows: list[dict[str, Any]]) -> dict[str, object]:
    """The report's table: counts by status, where the cases ran, solve times."""
    statuses = Counter(r["status"] for r in all_rows)
    ok = [r for r in all_rows if r["status"] == CONVERGED]
    hosts = Counter(f"{r['hostname']} ({str(r['node_id'])[:8]})" for r in all_rows
                    if r.get("node_id"))
    walls = [r["case_wall_s"] for r in ok if r.get("case_wall_s") is not None]
    return {
        "sweep": ", ".join(sorted({str(r["sweep"]) for r in all_rows})),
        "cases": len(all_rows),
        "status": dict(statuses.most_common()),
        "courses": ", ".join(sorted({Path(r["course"]).name for r in all_rows})),
        "riders": ", ".join(sorted({r["rider"] for r in all_rows})),
        "equipment": ", ".join(sorted({r["equipment"] for r in all_rows})),
        "models": ", ".join(sorted({r["model"] for r in all_rows})),
        "nodes": dict(hosts.most_common()),
        "median_case_wall_s": round(statistics.median(walls), 2) if walls else None,
    }


def _failures(rows: list[dict[str, Any]]) -> str:
    bad = [r for r in rows if r["status"] != CONVERGED]
    if not bad:
        return ""
    items = "".join(
        f"<li>{html.escape(r['status'])}: {html.escape(Path(r['course']).name)}, "
        f"{html.escape(r['rider'])} on {html.escape(r['equipment'])}, {r['model']}, wind "
        f"{r['wind_speed_mps'] * MPS_TO_KMH:.0f} km/h from {math.degrees(r['wind_from_rad']):.0f}"
        f" deg, grip {r['mu']:g}: {html.escape(r['reason'] or r['solver_status'] or '')}</li>"
        for r in bad[:_MAX_LISTED])
    more = f"<p>... and {len(bad) - _MAX_LISTED} more.</p>" if len(bad) > _MAX_LISTED else ""
    return (f"<h2>Cases left out of the figures ({len(bad)})</h2><ul>{items}</ul>{more}")


def render_html(all_rows: list[dict[str, Any]]) -> tuple[str, int]:
    """The report page and its figure count."""
    rows = [r for r in all_rows if r["status"] == CONVERGED]
    with mpl.rc_context({"figure.constrained_layout.use": True}):
        images = [png_bytes(fig, DPI) for fig in (_figures(rows) if rows else [])]
    table = "".join(f"<tr><th>{html.escape(k.replace('_', ' '))}</th>"
                    f"<td>{html.escape(table_cell(v))}</td></tr>"
                    for k, v in summary(all_rows).items())
    figures = "".join(f'<p><img alt="figure {i}" src="data:image/png;base64,'
                      f'{base64.b64encode(png).decode()}"></p>' for i, png in enumerate(images))
    title = html.escape(f"itt-planner sweep: {summary(all_rows)['sweep']}")
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{title}</title>"
            "<style>body{font-family:sans-serif;max-width:1250px;margin:auto}"
            "th{text-align:left;padding-right:2em}img{max-width:100%}</style></head><body>"
            f"<h1>{title}</h1><table>{table}</table>{figures}{_failures(all_rows)}"
            "</body></html>"), len(images)


def write_sweep_report(results: str | Path, output: str | Path) -> dict[str, object]:
    """Read a result dataset and write the HTML report; returns what went into it.

    Raises:
        IttError: no results there, or the report cannot be written.
    """
    rows = ResultStore(results).read().to_pylist()
    if not rows:
        raise IttError(f"{results}: no sweep results (run `itt-planner sweep` first)")
    output = Path(output)
    if output.suffix.lower() not in (".html", ".htm"):
        raise IttError(f"{output}: the sweep report is HTML (.html)")
    page, n_figures = render_html(rows)
    try:
        output.write_text(page, encoding="utf-8")
    except OSError as err:
        raise IttError(f"{output}: cannot write the report ({err})") from None
    return {"output": str(output), "cases": len(rows), "figures": n_figures,
            "converged": sum(r["status"] == CONVERGED for r in rows)}
