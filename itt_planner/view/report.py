"""A static report of a plan or a ride for people without Rerun: one self-contained HTML or a PNG.

The figures follow the paper's: power, speed and elevation against distance (with the
critical power and the corners marked), and for the tightest corners a close-up of the
planned line on the road (edges from w_L, w_R) coloured by speed, beside speed and lean
against distance. The report of a ride (`itt_planner.view.ride_report.RideTrace`, a replayed
log) draws what the rider did on top: actual and target power, actual speed and W'
against distance, and the GPS fixes and actual speed through the corners. Matplotlib
renders PNGs (Agg, no display) that the HTML embeds as base64, so the file can be mailed
as is.
"""

from __future__ import annotations

import base64
import html
import io
import math
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib as mpl
import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure, SubFigure

from itt_planner.course.geometry import Corner, Course
from itt_planner.errors import IttError
from itt_planner.model.rider import Rider
from itt_planner.ocp.plan import Plan
from itt_planner.units import MPS_TO_KMH
from itt_planner.view.report_sections import (
    ReportSection,
    draw_section,
    section_height_in,
    section_html,
    table_cell,
)
from itt_planner.view.ride_report import BeliefEvent, RideTrace, actual_finish_s, belief_events

#: Road shown before the entry and after the exit of a corner close-up (m).
CORNER_MARGIN_M = 60.0
#: Colour of everything the rider actually did (the Rerun recording's 'actual' orange).
ACTUAL = "darkorange"
#: Corners shown in close-up, tightest first.
MAX_CORNERS = 3
DPI = 110


@dataclass(frozen=True)
class ReportSettings:
    """What goes into the report."""

    max_corners: int = MAX_CORNERS
    corner_margin_m: float = CORNER_MARGIN_M
    dpi: int = DPI


def tightest_corners(course: Course, count: int) -> list[Corner]:
    """The `count` corners of smallest radius, in course order."""
    chosen = sorted(course.corners, key=lambda c: c.min_radius_m)[:count]
    return sorted(chosen, key=lambda c: c.apex_s_m)


def average_power_w(plan: Plan) -> float:
    """Time-weighted average pedalling power of a plan (braking counts as zero)."""
    dt = np.diff(plan.t_s)
    pedal = plan.pedal_power_w[:-1]
    return float(np.sum(pedal * dt) / np.sum(dt)) if np.sum(dt) > 0 else math.nan


def _clock(seconds: float) -> str:
    return f"{int(seconds // 60)}:{seconds % 60:04.1f}"


def summary(plan: Plan, course: Course, rider: Rider | None) -> dict[str, Any]:
    """The figures of the report's table (edge units: km, km/h, min:s, kJ)."""
    finish = plan.finish_time_s
    out: dict[str, Any] = {
        "course": course.name,
        "length_km": round(course.length_m / 1000, 3),
        "corners": len(course.corners),
        "model": plan.model,
        "solver_status": plan.solver_status,
        "finish_time": _clock(finish),
        "finish_time_s": round(finish, 2),
        "average_speed_kmh": round(course.length_m / finish * MPS_TO_KMH, 2),
        "average_power_w": round(average_power_w(plan), 1),
        "max_power_w": round(float(plan.power_w.max()), 1),
        "min_w_prime_kj": round(float(plan.w_prime_j.min()) / 1000, 2),
        "max_lean_deg": round(math.degrees(float(np.abs(plan.phi_rad).max())), 1),
        "max_friction_use": round(float(plan.friction_use.max()), 3),
    }
    if rider is not None:
        out["rider"] = rider.name
        out["critical_power_w"] = rider.critical_power_w
    return out


def ride_summary(trace: RideTrace, plan: Plan, course: Course,
                 rider: Rider | None) -> dict[str, Any]:
    """The figures of a ride report's table (edge units: km, km/h, min:s)."""
    finish = actual_finish_s(trace, course)
    statuses = Counter(trace.solver_status)
    events = belief_events(trace)
    out: dict[str, Any] = {
        "log": str(trace.path),
        "input": trace.metadata.get("input", ""),
        "course": course.name,
        "length_km": round(course.length_m / 1000, 3),
        "model": plan.model,
        "plan_finish_time": _clock(plan.finish_time_s),
        "plan_finish_time_s": round(plan.finish_time_s, 2),
        "finish_time": _clock(finish) if finish is not None else "not finished",
        "finish_time_s": round(finish, 2) if finish is not None else None,
        "finish_vs_plan_s": (round(finish - plan.finish_time_s, 2) if finish is not None
                             else None),
        "ride_duration_s": round(trace.duration_s, 2),
        "distance_km": round(max(float(trace.advice_s_m.max()),
                                 float(trace.power_s_m.max(initial=0.0))) / 1000, 3),
        # Meters report at a fixed rate: the sample mean is the time average (None: none).
        "average_power_w": round(float(trace.power_w.mean()), 1) if trace.power_w.size else None,
        "plan_average_power_w": round(average_power_w(plan), 1),
        "max_power_w": round(float(trace.power_w.max()), 1) if trace.power_w.size else None,
        "min_w_prime_kj": round(float(trace.w_prime_now_j.min()) / 1000, 2),
        "plan_min_w_prime_kj": round(float(plan.w_prime_j.min()) / 1000, 2),
        "advice": len(trace.solver_status),
        "fallbacks": int(trace.fallback.sum()),
        "solver_status": dict(statuses.most_common()),
        # What the engine planned with, from the advice (the plan drawn is the first).
        "cp_refits": sum(e.kind == "refit" for e in events),
        "plan_adoptions": sum(e.kind == "plan" for e in events),
        "belief_changes": [belief_text(e) for e in events],
    }
    cp_end = float(trace.cp_in_use_w[-1])
    if math.isfinite(cp_end):
        out["cp_in_use_end_w"] = round(cp_end, 1)
    if finish is not None:
        out["average_speed_kmh"] = round(course.length_m / finish * MPS_TO_KMH, 2)
    if rider is not None:
        out["rider"] = rider.name
        out["critical_power_w"] = rider.critical_power_w
    return out


def draw_overview(fig: Figure | SubFigure, plan: Plan, course: Course,
                  rider: Rider | None) -> None:
    """Power (pedalled: the plan's braking, to -2 kW at a hairpin, squashed the 0-1 kW; the
    speed shows it), speed and elevation against distance, corners shaded."""
    ax_p, ax_v, ax_z = fig.subplots(3, 1, sharex=True, height_ratios=[3, 3, 2])
    km = plan.s_m / 1000
    ax_p.plot(km, plan.pedal_power_w, color="tab:blue", lw=1.2, label="planned power")
    _critical_power(ax_p, rider)
    ax_p.set_ylabel("power (W)")
    ax_p.legend(loc="upper right", fontsize="small")
    ax_v.plot(km, plan.v_mps * MPS_TO_KMH, color="tab:blue", lw=1.2)
    ax_v.set_ylabel("speed (km/h)")
    _elevation(ax_z, course)
    _shade_corners((ax_p, ax_v, ax_z), course)
    fig.suptitle(f"{course.name}: plan ({plan.model}, finish {plan.finish_time_s:.1f} s); "
                 "corners shaded")


def draw_ride_overview(fig: Figure | SubFigure, ride: RideTrace, plan: Plan, course: Course,
                       rider: Rider | None) -> None:
    """The ride on the plan against distance: power (pedalled), speed, W', elevation."""
    ax_p, ax_v, ax_w, ax_z = fig.subplots(4, 1, sharex=True, height_ratios=[3, 3, 2, 2])
    km = plan.s_m / 1000
    ax_p.plot(km, plan.pedal_power_w, color="tab:blue", lw=1.2, label="planned power")
    ax_p.step(ride.advice_s_m / 1000, ride.target_power_w, where="post", color="tab:green",
              lw=1.0, label="target power (advice)")
    ax_p.plot(ride.power_s_m / 1000, ride.power_w, color=ACTUAL, lw=0.6, alpha=0.9,
              label="actual power" if ride.power_w.size else "actual power: no power meter")
    _critical_power(ax_p, rider)
    if np.isfinite(ride.cp_in_use_w).any():
        ax_p.step(ride.advice_s_m / 1000, ride.cp_in_use_w, where="post", color="tab:red",
                  lw=1.0, label="critical power in use (advice)")
    ax_p.set_ylabel("power (W)")
    ax_p.legend(loc="upper right", fontsize="small", ncols=2)
    ax_v.plot(ride.speed_s_m / 1000, ride.speed_mps * MPS_TO_KMH, color=ACTUAL, lw=0.8,
              label="actual speed")
    ax_v.plot(km, plan.v_mps * MPS_TO_KMH, color="tab:blue", lw=1.2, label="planned speed")
    ax_v.set_ylabel("speed (km/h)")
    ax_v.legend(loc="lower right", fontsize="small")
    ax_w.plot(ride.advice_s_m / 1000, ride.w_prime_now_j / 1000, color=ACTUAL, lw=1.2,
              label="actual W'")
    ax_w.plot(km, plan.w_prime_j / 1000, color="tab:blue", lw=1.2, label="planned W'")
    ax_w.set_ylabel("W' (kJ)")
    ax_w.legend(loc="lower left", fontsize="small")
    _elevation(ax_z, course)
    _shade_corners((ax_p, ax_v, ax_w, ax_z), course)
    events = belief_events(ride)
    _mark_belief_events((ax_p, ax_v, ax_w), events)
    fallbacks = int(ride.fallback.sum())
    refits = sum(e.kind == "refit" for e in events)
    fig.suptitle(f"{course.name}: ride (orange) against the plan ({plan.model}, blue)\n"
                 f"{len(ride.fallback)} advice, {fallbacks} fallbacks; {refits} CP refits "
                 f"(red dots), {len(events) - refits} plans adopted (blue dots); "
                 "corners shaded")


def belief_text(event: BeliefEvent) -> str:
    """One line of the report for a CP refit or a plan adoption (edge units: km, W)."""
    where = f"at {event.s_m / 1000:.2f} km"
    if event.kind == "refit":
        return f"CP in use {event.cp_before_w:.0f} -> {event.cp_after_w:.0f} W {where}"
    return f"plan {event.plan_version} adopted {where} (CP {event.cp_after_w:.0f} W)"


def _mark_belief_events(axes: tuple[Axes, ...], events: list[BeliefEvent]) -> None:
    """Dotted verticals where CP was refitted (red) or a re-solved plan adopted (blue);
    the planned curves drawn are the first plan's, the target power follows the adopted."""
    for event in events:
        colour = "tab:red" if event.kind == "refit" else "tab:blue"
        for ax in axes:
            ax.axvline(event.s_m / 1000, color=colour, ls=":", lw=1.2)


def _critical_power(ax: Axes, rider: Rider | None) -> None:
    if rider is not None:
        ax.axhline(rider.critical_power_w, color="tab:red", ls="--", lw=1,
                   label=f"critical power {rider.critical_power_w:.0f} W")


def _elevation(ax: Axes, course: Course) -> None:
    ax.fill_between(course.s_m / 1000, course.z_m, course.z_m.min() - 5, color="0.8")
    ax.plot(course.s_m / 1000, course.z_m, color="0.3", lw=1)
    ax.set_ylabel("elevation (m)")
    ax.set_xlabel("distance (km)")


def _shade_corners(axes: tuple[Axes, ...], course: Course) -> None:
    for ax in axes:
        for c in course.corners:
            ax.axvspan(c.entry_s_m / 1000, c.exit_s_m / 1000, color="tab:orange", alpha=0.15,
                       lw=0)
        ax.grid(alpha=0.3)


def draw_corner(fig: Figure | SubFigure, plan: Plan, course: Course, corner: Corner,
                margin_m: float = CORNER_MARGIN_M, ride: RideTrace | None = None) -> None:
    """The planned line on the road through one corner, and speed and lean across it.

    With a ride, its GPS fixes and wheel speed through the corner are drawn too.
    """
    ax_map, ax_v = fig.subplots(1, 2, width_ratios=[1, 1.3])
    s0 = max(0.0, corner.entry_s_m - margin_m)
    s1 = min(course.length_m, corner.exit_s_m + margin_m)
    s = course.s_m[(course.s_m >= s0) & (course.s_m <= s1)]
    for sign, width in ((1.0, course.at("width_left_m", s)), (-1.0, course.at("width_right_m", s))):
        x, y, _ = course.enu_at(s, sign * width)
        ax_map.plot(x, y, color="0.2", lw=1.5)
    x, y, _ = course.enu_at(s)
    ax_map.plot(x, y, color="0.6", lw=0.8, ls="--")
    k = (plan.s_m >= s0) & (plan.s_m <= s1)
    px, py, _ = course.enu_at(plan.s_m[k], plan.n_m[k])
    kmh = plan.v_mps[k] * MPS_TO_KMH
    segments = np.stack([np.column_stack([px[:-1], py[:-1]]),
                         np.column_stack([px[1:], py[1:]])], axis=1)
    lines = LineCollection(list(segments), cmap="viridis", lw=3)
    lines.set_array(0.5 * (kmh[:-1] + kmh[1:]))
    ax_map.add_collection(lines)
    fig.colorbar(lines, ax=ax_map, label="planned speed (km/h)", shrink=0.8)
    if ride is not None:
        g = (ride.gps_s_m >= s0) & (ride.gps_s_m <= s1)
        gx, gy, _ = course.from_geodetic(ride.gps_lat_deg[g], ride.gps_lon_deg[g],
                                         np.full(int(g.sum()), course.origin.alt_m))
        ax_map.plot(gx, gy, "o", color=ACTUAL, ms=3, label="GPS fixes")
        ax_map.legend(loc="best", fontsize="small")
    ax_map.set_aspect("equal", adjustable="datalim")
    ax_map.set_xlabel("east (m)")
    ax_map.set_ylabel("north (m)")
    ax_map.set_title("planned line (colour) between the road edges")
    d = plan.s_m[k] - corner.apex_s_m
    ax_v.plot(d, kmh, color="tab:blue", lw=1.5)
    if ride is not None:
        w = (ride.speed_s_m >= s0) & (ride.speed_s_m <= s1)
        ax_v.plot(ride.speed_s_m[w] - corner.apex_s_m, ride.speed_mps[w] * MPS_TO_KMH, ".-",
                  color=ACTUAL, lw=1, ms=3)
    ax_v.set_ylabel("speed (km/h)", color="tab:blue")
    ax_v.set_xlabel("distance from apex (m)")
    ax_lean = ax_v.twinx()
    ax_lean.plot(d, np.degrees(plan.phi_rad[k]), color="tab:red", lw=1.2)
    ax_lean.set_ylabel("lean (deg)", color="tab:red")
    ax_v.axvspan(corner.entry_s_m - corner.apex_s_m, corner.exit_s_m - corner.apex_s_m,
                 color="tab:orange", alpha=0.15, lw=0)
    ax_v.grid(alpha=0.3)
    fig.suptitle(f"{corner.direction} corner at {corner.apex_s_m / 1000:.2f} km: "
                 f"R {corner.min_radius_m:.0f} m, {math.degrees(corner.angle_rad):.0f} deg")


def png_bytes(fig: Figure, dpi: int) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def render_html(plan: Plan, course: Course, rider: Rider | None = None,
                settings: ReportSettings = ReportSettings(), ride: RideTrace | None = None,
                sections: tuple[ReportSection, ...] = ()) -> str:
    """The report as one self-contained HTML page (figures embedded as base64 PNG).

    With `ride`, the actual ride is drawn over the plan and the table compares them;
    `sections` follow the figures (the calibrated rider, the validation).
    """
    with mpl.rc_context({"figure.constrained_layout.use": True}):
        fig = Figure(figsize=(11, 8 if ride is None else 10))
        _draw_top(fig, plan, course, rider, ride)
        images = [png_bytes(fig, settings.dpi)]
        for corner in tightest_corners(course, settings.max_corners):
            fig = Figure(figsize=(11, 4.2))
            draw_corner(fig, plan, course, corner, settings.corner_margin_m, ride)
            images.append(png_bytes(fig, settings.dpi))
    table = summary(plan, course, rider) if ride is None else ride_summary(ride, plan, course,
                                                                            rider)
    rows = "".join(f"<tr><th>{html.escape(k.replace('_', ' '))}</th>"
                   f"<td>{html.escape(table_cell(v))}</td></tr>" for k, v in table.items())
    figures = "".join(f'<p><img alt="figure {i}" src="data:image/png;base64,'
                      f'{base64.b64encode(png).decode()}"></p>' for i, png in enumerate(images))
    kind = "report" if ride is None else "ride report"
    title = html.escape(f"itt-planner {kind}: {course.name}")
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{title}</title>"
            "<style>body{font-family:sans-serif;max-width:1250px;margin:auto}"
            "th{text-align:left;padding-right:2em}img{max-width:100%}"
            "table.grid td{padding-right:1em}</style></head><body>"
            f"<h1>{title}</h1><table>{rows}</table>{figures}"
            f"{''.join(section_html(x) for x in sections)}</body></html>")


def _draw_top(fig: Figure | SubFigure, plan: Plan, course: Course, rider: Rider | None,
              ride: RideTrace | None) -> None:
    if ride is None:
        draw_overview(fig, plan, course, rider)
    else:
        draw_ride_overview(fig, ride, plan, course, rider)


def render_png(plan: Plan, course: Course, rider: Rider | None = None,
               settings: ReportSettings = ReportSettings(), ride: RideTrace | None = None,
               sections: tuple[ReportSection, ...] = ()) -> bytes:
    """The overview, the tightest corner and `sections` (their text and images) in one PNG."""
    corners = tightest_corners(course, 1)
    top_in, width_in = (8.0 if ride is None else 10.0), 11.0
    heights = [top_in] + [4.2] * len(corners) + [section_height_in(x, width_in)
                                                   for x in sections]
    with mpl.rc_context({"figure.constrained_layout.use": True}):
        fig = Figure(figsize=(width_in, sum(heights)))
        # squeeze=False: always an array of subfigures (one column), even for one row.
        top, *rest = fig.subfigures(len(heights), 1, squeeze=False,
                                    height_ratios=heights)[:, 0]
        _draw_top(top, plan, course, rider, ride)
        for sub, corner in zip(rest, corners, strict=False):
            draw_corner(sub, plan, course, corner, settings.corner_margin_m, ride)
        for sub, section in zip(rest[len(corners):], sections, strict=True):
            draw_section(sub, section, width_in)
        return png_bytes(fig, settings.dpi)


def write_report(plan: Plan, course: Course, output: str | Path, rider: Rider | None = None,
                 settings: ReportSettings = ReportSettings(), ride: RideTrace | None = None,
                 sections: tuple[ReportSection, ...] = ()) -> Path:
    """Write the report as HTML (`.html`/`.htm`) or PNG (`.png`), by the output's suffix.

    `sections` follow the figures in both (the PNG draws their text and images).

    Raises:
        IttError: another suffix, the plan is not on this course, or the file cannot be written.
    """
    output = Path(output)
    if plan.s_m[-1] > course.length_m + 1.0:
        msg = (f"plan ends at {plan.s_m[-1]:.0f} m but course {course.name!r} is "
               f"{course.length_m:.0f} m long: wrong --course?")
        raise IttError(msg)
    suffix = output.suffix.lower()
    try:
        if suffix in (".html", ".htm"):
            output.write_text(render_html(plan, course, rider, settings, ride, sections),
                              encoding="utf-8")
        elif suffix == ".png":
            output.write_bytes(render_png(plan, course, rider, settings, ride, sections))
        else:
            raise IttError(f"{output}: report must be .html or .png")
    except OSError as err:
        raise IttError(f"{output}: cannot write the report ({err})") from None
    return output


def rider_from_plan(plan: Plan) -> Rider | None:
    """The rider a plan was solved for, when its header records it (`meta["rider"]`)."""
    fields = plan.meta.get("rider")
    if not isinstance(fields, dict):
        return None
    try:
        return Rider(**fields)
    except (TypeError, IttError):
        return None
