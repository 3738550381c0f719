"""HTML reports of a calibration and a validation (matplotlib figures, base64 PNG).

Calibration: the virtual-elevation plot (recorded altitude against the altitude the
fitted power balance explains, on the stretches used), the power-duration curve with
both critical-power models, and corner apex speeds against radius with the fitted
lateral-acceleration limit. Validation: ride speed against each model's speed over
distance, and the plan's speed and power against the ride's.
"""

from __future__ import annotations

import base64
import html
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib as mpl
import numpy as np
from matplotlib.figure import Figure

from itt_planner.calibration.ride_data import CalibrationError
from itt_planner.units import MPS_TO_KMH
from itt_planner.view.report import png_bytes

if TYPE_CHECKING:
    from itt_planner.calibration.calibrate import CalibrationResult
    from itt_planner.calibration.validate import Validation


def _png(fig: Figure) -> str:
    """The figure as base64 PNG text for an <img> data URL."""
    return base64.b64encode(png_bytes(fig, 90)).decode()


def _page(title: str, summary: dict[str, Any], images: list[str]) -> str:
    body = "".join(f'<p><img alt="figure {i}" src="data:image/png;base64,{png}"></p>'
                   for i, png in enumerate(images))
    text = html.escape(json.dumps(summary, indent=1, default=str))
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}"
            "</title><style>body{font-family:sans-serif;max-width:1250px;margin:auto}"
            "img{max-width:100%}pre{font-size:small}</style></head><body>"
            f"<h1>{html.escape(title)}</h1>{body}<pre>{text}</pre></body></html>")


def calibration_figures(result: CalibrationResult) -> list[str]:
    """The three calibration figures as base64 PNGs (those whose fit exists)."""
    images = []
    with mpl.rc_context({"figure.constrained_layout.use": True}):
        if result.aero is not None:
            ride, a = result.rides[0], result.aero
            fig = Figure(figsize=(11, 4))
            ax = fig.subplots()
            ax.plot(ride.dist_m / 1000, ride.ele_m, color="0.6", lw=1, label="recorded")
            ax.plot(ride.dist_m / 1000, a.virtual_ele_m, color="tab:red", lw=1,
                    label=f"virtual (CdA {a.cda_m2:.3f}, crr {a.crr:.4f})")
            ax.set_xlabel("distance (km)")
            ax.set_ylabel("elevation (m)")
            ax.set_title(f"virtual elevation, {a.n_stretches} stretches, RMSE {a.rmse_m:.2f} m")
            ax.legend()
            images.append(_png(fig))
        if result.mmp_w:
            fig = Figure(figsize=(11, 4))
            ax = fig.subplots()
            t = np.array(sorted(result.mmp_w), float)
            ax.semilogx(t, [result.mmp_w[int(d)] for d in t], "ko", ms=4, label="mean-maximal")
            grid = np.geomspace(t[0], t[-1], 200)
            for fit, style in ((result.cp_2p, "tab:blue"), (result.cp_3p, "tab:orange")):
                if fit is not None:
                    ax.semilogx(grid, fit.predict(grid), color=style,
                                label=f"{fit.model}: CP {fit.cp_w:.0f} W, W' {fit.w_prime_j:.0f} J")
            ax.set_ylim(0, max(result.mmp_w.values()) * 1.1)
            ax.set_xlabel("duration (s)")
            ax.set_ylabel("power (W)")
            ax.legend()
            images.append(_png(fig))
        if result.cornering is not None:
            c = result.cornering
            fig = Figure(figsize=(11, 4))
            ax = fig.subplots()
            r = np.array([k.radius_m for k in c.corners])
            ax.plot(r, [MPS_TO_KMH * k.speed_mps for k in c.corners], "ko", ms=4,
                    label="apex speed")
            grid = np.linspace(max(r.min() * 0.8, 1.0), r.max() * 1.2, 100)
            ax.plot(grid, MPS_TO_KMH * np.sqrt(c.max_lateral_accel_mps2 * grid), "tab:red",
                    label=f"a_y = {c.max_lateral_accel_mps2:.2f} m/s^2")
            ax.set_xlabel("corner radius (m)")
            ax.set_ylabel("speed (km/h)")
            ax.legend()
            images.append(_png(fig))
    return images


def validation_figures(val: Validation) -> list[str]:
    """Speed over distance (ride, models), and plan against ride, as base64 PNGs."""
    images = []
    s = val.on_course.s_m / 1000
    with mpl.rc_context({"figure.constrained_layout.use": True}):
        fig = Figure(figsize=(11, 4))
        ax = fig.subplots()
        ax.plot(s, MPS_TO_KMH * val.on_course.v_mps, color="0.4", lw=1, label="ride (5 s)")
        for run in val.runs:
            ax.plot(s, MPS_TO_KMH * run.v_mps, lw=1,
                    label=f"{run.model} ({run.label}), ride's power")
        ax.set_xlabel("distance (km)")
        ax.set_ylabel("speed (km/h)")
        ax.legend()
        images.append(_png(fig))
        for plan in val.plans:
            fig = Figure(figsize=(11, 5))
            ax_v, ax_p = fig.subplots(2, 1, sharex=True)
            ax_v.plot(s, MPS_TO_KMH * val.on_course.v_mps, color="0.4", lw=1, label="ride")
            ax_v.plot(plan.s_m / 1000, MPS_TO_KMH * plan.v_mps, lw=1, label=f"plan {plan.model}")
            ax_v.set_ylabel("speed (km/h)")
            ax_v.legend()
            ax_p.plot(s, val.on_course.power_w, color="0.4", lw=0.6, label="ride")
            ax_p.plot(plan.s_m / 1000, plan.pedal_power_w, lw=1, label="plan")
            ax_p.set_ylabel("power (W)")
            ax_p.set_xlabel("distance (km)")
            images.append(_png(fig))
    return images


def _write(path: Path, text: str) -> Path:
    try:
        path.write_text(text, encoding="utf-8")
    except OSError as err:
        raise CalibrationError(f"{path}: cannot write the report ({err})") from None
    return path


def write_calibration_report(result: CalibrationResult, path: str | Path) -> Path:
    """Write the calibration report (HTML).

    Raises:
        CalibrationError: the file cannot be written.
    """
    summary = result.as_dict()
    return _write(Path(path), _page("itt-planner calibration", summary,
                                    calibration_figures(result)))


def write_validation_report(val: Validation, path: str | Path) -> Path:
    """Write the validation report (HTML).

    Raises:
        CalibrationError: the file cannot be written.
    """
    return _write(Path(path), _page(f"itt-planner validation: {val.course.name}", val.figures,
                                    validation_figures(val)))
