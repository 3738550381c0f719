"""The rider's estimated state, the estimator's output and the planner's input."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class RiderState:
    """Where the rider is on the course and what is left in the tank.

    Attributes:
        s_m: arc length along the course centre line from the start line.
        n_m: lateral offset from the centre line, positive to the left.
        heading_rad: absolute heading, ENU, counter-clockwise from East.
        w_prime_j: remaining anaerobic capacity W' (J).
        elapsed_s: time since the start of the ride (s).
        gps_fresh: False while dead-reckoning through a GPS dropout.
    """

    stamp_s: float
    s_m: float
    n_m: float
    speed_mps: float
    heading_rad: float
    power_w: float
    w_prime_j: float
    elapsed_s: float
    gps_fresh: bool = True
