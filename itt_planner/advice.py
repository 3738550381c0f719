"""What the pacing engine tells the team car: the `Advice` and its `Diagnostic`s."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from itt_planner.state import RiderState


class Level(IntEnum):
    """Diagnostic levels, the values of ROS `diagnostic_msgs/DiagnosticStatus`."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3


@dataclass(frozen=True)
class Diagnostic:
    """One health item (solver, inputs, fallbacks), stamped on the ride clock."""

    stamp_s: float
    name: str
    level: Level
    message: str
    values: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class Advice:
    """The plan over the horizon from the rider's current state.

    `horizon_*` arrays share the grid `horizon_s_m` (arc length on the course); the line
    is given both in the ENU `map` frame and in WGS84. `fallback` is True when the last
    solve failed or overran and this advice is the last good plan, shifted.
    """

    stamp_s: float
    state: RiderState
    target_power_w: float
    horizon_s_m: np.ndarray
    horizon_power_w: np.ndarray
    horizon_speed_mps: np.ndarray
    horizon_n_m: np.ndarray
    line_x_m: np.ndarray
    line_y_m: np.ndarray
    line_z_m: np.ndarray
    line_lat_deg: np.ndarray
    line_lon_deg: np.ndarray
    predicted_finish_s: float
    w_prime_now_j: float
    w_prime_finish_j: float
    solver_status: str
    iterations: int
    solve_time_s: float
    fallback: bool = False
