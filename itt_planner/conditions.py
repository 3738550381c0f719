"""Environmental conditions of a ride: grip of the road, wind and air density.

Wind is given at the edge in the meteorological convention (speed, direction the wind
blows FROM, clockwise from North) and converted here, once, to an ENU velocity vector.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from itt_planner.errors import RiderError
from itt_planner.rider import PAPER_AIR_DENSITY_KGPM3

GRAVITY_MPS2 = 9.81


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
        return cls(mu_x=mu, mu_y=mu, wind_speed_mps=wind_kmh / 3.6,
                   wind_from_rad=math.radians(wind_from_deg))

    def wind_enu_mps(self) -> tuple[float, float]:
        """Wind velocity (east, north) in m/s: where the air moves TO."""
        return (-self.wind_speed_mps * math.sin(self.wind_from_rad),
                -self.wind_speed_mps * math.cos(self.wind_from_rad))
