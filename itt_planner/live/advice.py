"""What the pacing engine tells the team car: the `Advice`, its `Cue` and `Diagnostic`s."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from itt_planner.model.state import RiderState


class Level(IntEnum):
    """Diagnostic levels, the values of ROS `diagnostic_msgs/DiagnosticStatus`."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3


class Cue(IntEnum):
    """What the rider should do now besides holding `target_power_w` (the values of the
    `cue` field of `itt_msgs/Advice` and `itt_msgs/TargetPower`).

    PEDAL: hold the target power. COAST: stop pedalling (the plan's power here is about
    zero: a lean too deep to pedal, C15, or a descent). BRAKE: brake (the plan's power at
    the contact point is a braking force, model.md section 2); the target speed at the
    next corner apex says to what. CLIMB: a climb starts: go to the target power now
    (held over the foot of the climb).
    """

    PEDAL = 0
    COAST = 1
    BRAKE = 2
    CLIMB = 3


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
    is given both in the ENU `map` frame and in WGS84. `horizon_power_w` is the planner's
    power at the contact point, negative where it brakes (model.md section 2);
    `target_power_w` is what a rider can follow: never below 0 W, rate-limited between
    advices except at a change of `cue` (`advice_shaping`). `fallback` is True when the
    last solve failed or overran and this advice is the last good plan, shifted.

    `corner_speed_mps` / `corner_distance_m`: the advised speed at the apex of the next
    corner within the horizon and the distance to that apex (NaN when none).
    `cp_in_use_w`, `plan_version`: the critical power the engine plans with now (after
    any refit) and the version of the full-course plan in force (0: the plan the engine
    started with; +1 at every adoption of a re-solved plan).
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
    cue: Cue = Cue.PEDAL
    corner_speed_mps: float = math.nan
    corner_distance_m: float = math.nan
    cp_in_use_w: float = math.nan
    plan_version: int = 0
