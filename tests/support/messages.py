"""A full `Advice` with every field set, for message, log and DDS round trips."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from itt_planner.live.advice import Advice, Cue
from itt_planner.model.state import RiderState


def make_advice(stamp_s: float = 1_700_000_123.25, n: int = 25) -> Advice:
    state = RiderState(stamp_s=stamp_s, s_m=1234.5, n_m=-0.4, speed_mps=12.3,
                       heading_rad=0.7, power_w=310.0, w_prime_j=15_000.0, elapsed_s=100.5,
                       gps_fresh=False)
    s = 1234.5 + np.linspace(0.0, 1000.0, n)
    return Advice(
        stamp_s=stamp_s, state=state, target_power_w=305.5, horizon_s_m=s,
        horizon_power_w=300 + 10 * np.sin(s / 100), horizon_speed_mps=12 + np.cos(s / 50),
        horizon_n_m=0.5 * np.sin(s / 200), line_x_m=np.cos(s / 300) * 300,
        line_y_m=np.sin(s / 300) * 300, line_z_m=s * 0.02, line_lat_deg=45 + s * 1e-6,
        line_lon_deg=11 + s * 1e-6, predicted_finish_s=1795.25, w_prime_now_j=15_000.0,
        w_prime_finish_j=250.0, solver_status="Solve_Succeeded", iterations=17,
        solve_time_s=0.031, fallback=True, cue=Cue.BRAKE, corner_speed_mps=8.25,
        corner_distance_m=87.5, cp_in_use_w=412.5, plan_version=3)


def make_advice_without_corner() -> Advice:
    """The advice of `make_advice` as the engine makes it on a straight, pedalling."""
    return dataclasses.replace(make_advice(), cue=Cue.PEDAL, corner_speed_mps=math.nan,
                               corner_distance_m=math.nan)
