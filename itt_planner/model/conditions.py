"""Environmental conditions of a ride: grip of the road, wind and air density.

Wind is given at the edge in the meteorological convention (speed, direction the wind
blows FROM, clockwise from North) and converted here, once, to an ENU velocity vector.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from itt_planner.errors import RiderError
from itt_planner.model.rider import PAPER_AIR_DENSITY_KGPM3
from itt_planner.units import MPS_TO_KMH

GRAVITY_MPS2 = 9.81

#: Standard atmosphere (ICAO): sea-level pressure (Pa), lapse-rate exponent, scale.
_P0_PA = 101_325.0
_BARO_K_PER_M = 2.25577e-5
_BARO_EXP = 5.25588
#: Specific gas constant of dry air, J/(kg K).
_R_DRY = 287.05
#: The air temperatures (C) a plan takes: a race is ridden within them.
AIR_TEMPERATURE_RANGE_C = (-30.0, 50.0)
#: Temperature used when neither the record nor the caller gives one (15 C, ISA).
DEFAULT_TEMPERATURE_C = 15.0


def air_density_kgpm3(altitude_m: np.ndarray | float, temperature_c: np.ndarray | float
                      ) -> np.ndarray:
    """Dry-air density from the ISA pressure at `altitude_m` and the air temperature.

    rho = p / (R T), p = p0 (1 - 2.25577e-5 h)^5.25588 (ISA troposphere).
    """
    h = np.asarray(altitude_m, float)
    pressure = _P0_PA * (1.0 - _BARO_K_PER_M * h) ** _BARO_EXP
    return pressure / (_R_DRY * (np.asarray(temperature_c, float) + 273.15))


def day_air_density_kgpm3(mean_altitude_m: float, temperature_c: float) -> float:
    """The air of a race day at `temperature_c` on a course at `mean_altitude_m`
    (`air_density_kgpm3`): a plan's one density.

    Raises:
        RiderError: a temperature outside `AIR_TEMPERATURE_RANGE_C` (not a race day's).
    """
    low, high = AIR_TEMPERATURE_RANGE_C
    if not low <= temperature_c <= high:
        msg = f"conditions: air temperature {temperature_c!r} C, expected {low:.0f} to {high:.0f}"
        raise RiderError(msg)
    return float(air_density_kgpm3(mean_altitude_m, temperature_c))


def own_air_note(mean_altitude_m: float, assumed_kgpm3: float,
                 recorded_temperature_c: float = math.nan) -> str | None:
    """The air at a course's mean altitude when it differs from the density a plan
    assumes by more than 3 % (drag scales with it), else None: at the temperature a ride's
    records give (`recorded_temperature_c`), else ISA's 15 C."""
    recorded = math.isfinite(recorded_temperature_c)
    temperature_c = recorded_temperature_c if recorded else DEFAULT_TEMPERATURE_C
    own = float(air_density_kgpm3(mean_altitude_m, temperature_c))
    if abs(own / assumed_kgpm3 - 1.0) <= 0.03:
        return None
    if recorded:
        return (f"the plan assumes air at {assumed_kgpm3:.2f} kg/m^3; the ride's records "
                f"give {temperature_c:.1f} C, and at the course's mean altitude, "
                f"{mean_altitude_m:.0f} m, that air is {own:.2f}: --air-temperature-c "
                f"{temperature_c:.1f} (plan, replay; the node's air_temperature_c) plans in it")
    return (f"the plan assumes air at {assumed_kgpm3:.2f} kg/m^3; at the course's mean "
            f"altitude, {mean_altitude_m:.0f} m, it is {own:.2f} at "
            f"{DEFAULT_TEMPERATURE_C:.0f} C (ISA): --air-density-kgpm3 {own:.2f}, or "
            "--air-temperature-c with the day's temperature (plan, replay; the node's "
            "air_density_kgpm3, air_temperature_c) plans in it")


@dataclass(frozen=True)
class Conditions:
    """Road grip (model.md C16), wind (E3) and air density. Defaults: dry, still air."""

    mu_x: float = 1.0
    mu_y: float = 1.0
    wind_speed_mps: float = 0.0
    wind_from_rad: float = 0.0
    air_density_kgpm3: float = PAPER_AIR_DENSITY_KGPM3

    def __post_init__(self) -> None:
        for field in ("mu_x", "mu_y", "air_density_kgpm3"):
            value = getattr(self, field)
            if not math.isfinite(value) or value <= 0:
                msg = f"conditions: {field} must be positive, got {value!r}"
                raise RiderError(msg)
        if not math.isfinite(self.wind_speed_mps) or self.wind_speed_mps < 0:
            msg = f"conditions: wind_speed_mps must be >= 0, got {self.wind_speed_mps!r}"
            raise RiderError(msg)

    @classmethod
    def from_meteo(cls, *, wind_kmh: float = 0.0, wind_from_deg: float = 0.0,
                   mu: float = 1.0) -> Conditions:
        """Build from edge units: wind speed in km/h, direction FROM in degrees (0 = North)."""
        return cls(mu_x=mu, mu_y=mu, wind_speed_mps=wind_kmh / MPS_TO_KMH,
                   wind_from_rad=math.radians(wind_from_deg))

    def with_lateral_grip(self, fraction: float) -> Conditions:
        """These conditions with `mu_y` scaled by `fraction` (0 < fraction <= 1).

        For planning what a rider can follow: a rider who keeps part of the lateral grip
        as headroom in a steady turn (the virtual rider of `simulate`) cannot ride a plan
        that corners at 100 % of `mu_y`, so the optimum for that rider is the plan for
        the grip it uses. In the model `mu_y` enters only C16's lateral term (and the
        OCP's initial guess of corner speeds).

        Raises:
            RiderError: `fraction` outside (0, 1].
        """
        if not (math.isfinite(fraction) and 0 < fraction <= 1):
            msg = f"conditions: lateral grip fraction must be in (0, 1], got {fraction!r}"
            raise RiderError(msg)
        return dataclasses.replace(self, mu_y=self.mu_y * fraction)

    def wind_enu_mps(self) -> tuple[float, float]:
        """Wind velocity (east, north) in m/s: where the air moves TO."""
        return (-self.wind_speed_mps * math.sin(self.wind_from_rad),
                -self.wind_speed_mps * math.cos(self.wind_from_rad))
