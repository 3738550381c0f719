"""A static report of a plan for people without Rerun: one self-contained HTML file or a PNG.

The figures follow the paper's: power, speed and elevation against distance (with the
critical power and the corners marked), and for the tightest corners a close-up of the
planned line on the road (edges from w_L, w_R) coloured by speed, beside speed and lean
against distance. Matplotlib renders PNGs (Agg, no display) that the HTML embeds as
base64, so the file can be mailed as is.
"""

from __future__ import annotations

import base64
import html
import io
import math
from dataclasses import dataclass
from pathlib import Path

import matplotlib as mpl
import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure, SubFigure

from itt_planner.course import Corner, Course
from itt_planner.errors import IttError
from itt_planner.plan import Plan
from itt_planner.rider import Rider

MPS_TO_KMH = 3.6
#: Road shown before the entry and after the exit of a corner close-up (m).
CORNER_MARGIN_M = 60.0
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


def summary(plan: Plan, course: Course, rider: Rider | None) -> dict[str, object]:
    """The figures of the report's table (edge units: km, km/h, min:s, kJ)."""
    dt = np.diff(plan.t_s)
    pedal = np.clip(plan.power_w[:-1], 0.0, None)
    avg_power = float(np.sum(pedal * dt) / np.sum(dt)) if np.sum(dt) > 0 else math.nan
    finish = plan.finish_time_s
    out: dict[str, object] = {
        "course": course.name,
        "length_km": round(course.length_m / 1000, 3),
        "corners": len(course.corners),
        "model": plan.model,
        "solver_status": plan.solver_status,
        "finish_time": f"{int(finish // 60)}:{finish % 60:04.1f}",
        "finish_time_s": round(finish, 2),
        "average_speed_kmh": round(course.length_m / finish * MPS_TO_KMH, 2),
        "average_power_w": round(avg_power, 1),
        "max_power_w": round(float(plan.power_w.max()), 1),
        "min_w_prime_kj": round(float(plan.w_prime_j.min()) / 1000, 2),
        "max_lean_deg": round(math.degrees(float(np.abs(plan.phi_rad).max())), 1),
        "max_friction_use": round(float(plan.friction_use.max()), 3),
    }
    if rider is not None:
        out["rider"] = rider.name
        out["critical_power_w"] = rider.critical_power_w
    return out


def draw_overview(fig: Figure | SubFigure, plan: Plan, course: Course,
                  rider: Rider | None) -> None:
    """Power, speed and elevation against distance, corners shaded."""
    ax_p, ax_v, ax_z = fig.subplots(3, 1, sharex=True, height_ratios=[3, 3, 2])
    km = plan.s_m / 1000
    ax_p.plot(km, plan.power_w, color="tab:blue", lw=1.2, label="planned power")
    if rider is not None:
        ax_p.axhline(rider.critical_power_w, color="tab:red", ls="--", lw=1,
                     label=f"critical power {rider.critical_power_w:.0f} W")
    ax_p.set_ylabel("power (W)")
    ax_p.legend(loc="upper right", fontsize="small")
    ax_v.plot(km, plan.v_mps * MPS_TO_KMH, color="tab:blue", lw=1.2)
    ax_v.set_ylabel("speed (km/h)")
    ax_z.fill_between(course.s_m / 1000, course.z_m, course.z_m.min() - 5, color="0.8")
    ax_z.plot(course.s_m / 1000, course.z_m, color="0.3", lw=1)
    ax_z.set_ylabel("elevation (m)")
    ax_z.set_xlabel("distance (km)")
    for ax in (ax_p, ax_v, ax_z):
        for c in course.corners:
            ax.axvspan(c.entry_s_m / 1000, c.exit_s_m / 1000, color="tab:orange", alpha=0.15,
                       lw=0)
        ax.grid(alpha=0.3)
    fig.suptitle(f"{course.name}: plan ({plan.model}, finish {plan.finish_time_s:.1f} s); "
                 "corners shaded")


def draw_corner(fig: Figure | SubFigure, plan: Plan, course: Course, corner: Corner,
                margin_m: float = CORNER_MARGIN_M) -> None:
    """The planned line on the road through one corner, and speed and lean across it."""
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
    lines = LineCollection(segments, cmap="viridis", lw=3)
    lines.set_array(0.5 * (kmh[:-1] + kmh[1:]))
    ax_map.add_collection(lines)
    fig.colorbar(lines, ax=ax_map, label="planned speed (km/h)", shrink=0.8)
    ax_map.set_aspect("equal", adjustable="datalim")
    ax_map.set_xlabel("east (m)")
    ax_map.set_ylabel("north (m)")
    ax_map.set_title("planned line (colour) between the road edges")
    d = plan.s_m[k] - corner.apex_s_m
    ax_v.plot(d, kmh, color="tab:blue", lw=1.5)
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


def _png(fig: Figure, dpi: int) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def render_html(plan: Plan, course: Course, rider: Rider | None = None,
                settings: ReportSettings = ReportSettings()) -> str:
    """The report as one self-contained HTML page (figures embedded as base64 PNG)."""
    with mpl.rc_context({"figure.constrained_layout.use": True}):
        fig = Figure(figsize=(11, 8))
        draw_overview(fig, plan, course, rider)
        images = [_png(fig, settings.dpi)]
        for corner in tightest_corners(course, settings.max_corners):
            fig = Figure(figsize=(11, 4.2))
            draw_corner(fig, plan, course, corner, settings.corner_margin_m)
            images.append(_png(fig, settings.dpi))
    rows = "".join(f"<tr><th>{html.escape(k.replace('_', ' '))}</th>"
                   f"<td>{html.escape(str(v))}</td></tr>"
                   for k, v in summary(plan, course, rider).items())
    figures = "".join(f'<p><img alt="figure {i}" src="data:image/png;base64,'
                      f'{base64.b64encode(png).decode()}"></p>' for i, png in enumerate(images))
    title = html.escape(f"itt-planner report: {course.name}")
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{title}</title>"
            "<style>body{font-family:sans-serif;max-width:1250px;margin:auto}"
            "th{text-align:left;padding-right:2em}img{max-width:100%}</style></head><body>"
            f"<h1>{title}</h1><table>{rows}</table>{figures}</body></html>")


def render_png(plan: Plan, course: Course, rider: Rider | None = None,
               settings: ReportSettings = ReportSettings()) -> bytes:
    """The overview and the tightest corner in one PNG."""
    corners = tightest_corners(course, 1)
    with mpl.rc_context({"figure.constrained_layout.use": True}):
        fig = Figure(figsize=(11, 8 + 4.2 * len(corners)))
        top, *rest = fig.subfigures(1 + len(corners), 1,
                                    height_ratios=[8] + [4.2] * len(corners))
        draw_overview(top, plan, course, rider)
        for sub, corner in zip(rest, corners, strict=True):
            draw_corner(sub, plan, course, corner, settings.corner_margin_m)
        return _png(fig, settings.dpi)


def write_report(plan: Plan, course: Course, output: str | Path, rider: Rider | None = None,
                 settings: ReportSettings = ReportSettings()) -> Path:
    """Write the report as HTML (`.html`/`.htm`) or PNG (`.png`), by the output's suffix.

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
            output.write_text(render_html(plan, course, rider, settings), encoding="utf-8")
        elif suffix == ".png":
            output.write_bytes(render_png(plan, course, rider, settings))
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
