"""Timestamped sensor inputs of the core, in SI units, independent of ROS.

Stamps are seconds on the ride's clock (POSIX time for recorded rides); nothing in the
core reads the wall clock. `itt_msgs_py` converts ROS messages to and from these.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class GpsFix:
    """A GNSS fix (WGS84). `std_m` is the horizontal 1-sigma, NaN when unknown."""

    stamp_s: float
    lat_deg: float
    lon_deg: float
    alt_m: float
    std_m: float = math.nan


@dataclass(frozen=True)
class WheelSpeed:
    """Forward speed of the bicycle from the wheel sensor (m/s)."""

    stamp_s: float
    speed_mps: float


@dataclass(frozen=True)
class PowerReading:
    """Power at the pedals (W); cadence in rpm, NaN when the meter gives none."""

    stamp_s: float
    power_w: float
    cadence_rpm: float = math.nan


Sample = GpsFix | WheelSpeed | PowerReading
