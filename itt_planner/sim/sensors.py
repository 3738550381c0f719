"""Simulated GPS, wheel-speed and power sensors sampling a true trajectory at their rates,
with a wandering GPS bias, dropouts and outliers; and a recorded ride as a head unit on
smart recording would have kept it."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.course.track_files import Recording
from itt_planner.live.samples import GpsFix, PowerReading, Sample, WheelSpeed


@dataclass(frozen=True)
class SensorSettings:
    """Noise of the simulated sensors.

    GPS error is a slowly wandering bias (first-order Gauss-Markov, `gps_tau_s`) plus
    white noise: consecutive bike-GPS fixes are strongly correlated, which is what makes
    map matching hard. `gps_std_m` is the total horizontal 1-sigma per axis.

    Attributes:
        gps_period_s: fix interval (1 Hz).
        wheel_scale: the wheel sensor's circumference error (1.01 = reads 1 % fast).
        dropouts: (start, duration) intervals of ride time without GPS.
        outliers: ride times at which the fix jumps `outlier_m` sideways.
    """

    gps_period_s: float = 1.0
    gps_std_m: float = 3.0
    gps_tau_s: float = 20.0
    gps_white_fraction: float = 0.3
    speed_period_s: float = 1.0
    speed_std_mps: float = 0.15
    wheel_scale: float = 1.01
    power_period_s: float = 1.0
    power_std_w: float = 8.0
    dropouts: tuple[tuple[float, float], ...] = ()
    outliers: tuple[float, ...] = ()
    outlier_m: float = 100.0


class Sensors:
    """GPS, wheel-speed and power sensors sampling a true trajectory at their own rates.

    Args:
        course: for ENU <-> lat/lon.
        settings: noise levels, dropouts and outliers.
        rng: the random stream (seeded by the caller for reproducible rides).
        t0_s: stamp of ride time 0 (POSIX seconds for a realistic log).
    """

    def __init__(self, course: Course, settings: SensorSettings, rng: np.random.Generator,
                 t0_s: float = 0.0) -> None:
        self.course, self.settings, self.rng, self.t0_s = course, settings, rng, t0_s
        st = settings
        self._white = st.gps_std_m * math.sqrt(st.gps_white_fraction)
        self._bias_std = st.gps_std_m * math.sqrt(1 - st.gps_white_fraction)
        self._bias = rng.normal(0.0, self._bias_std, 2)
        self._next = {"gps": 0.0, "speed": 0.0, "power": 0.0}

    def sample(self, t: float, s_m: float, n_m: float, v_mps: float, power_w: float
               ) -> list[Sample]:
        """The samples due at ride time `t` (each sensor fires once its period is up)."""
        st = self.settings
        out: list[Sample] = []
        eps = 1e-9
        if t + eps >= self._next["gps"]:
            self._next["gps"] += st.gps_period_s
            fix = self._gps(t, s_m, n_m)
            if fix is not None:
                out.append(fix)
        if t + eps >= self._next["speed"]:
            self._next["speed"] += st.speed_period_s
            v = v_mps * st.wheel_scale + self.rng.normal(0.0, st.speed_std_mps)
            out.append(WheelSpeed(self.t0_s + t, max(v, 0.0)))
        if t + eps >= self._next["power"]:
            self._next["power"] += st.power_period_s
            # A power meter measures pedalling only: braking reads as zero.
            p = max(power_w + self.rng.normal(0.0, st.power_std_w), 0.0) if power_w > 0 else 0.0
            out.append(PowerReading(self.t0_s + t, p))
        return out

    def _gps(self, t: float, s_m: float, n_m: float) -> GpsFix | None:
        st = self.settings
        a = math.exp(-st.gps_period_s / st.gps_tau_s)
        self._bias = a * self._bias + math.sqrt(1 - a * a) * self.rng.normal(
            0.0, self._bias_std, 2)
        if any(d0 <= t < d0 + dur for d0, dur in st.dropouts):
            return None
        x, y, z = (float(c) for c in self.course.enu_at(s_m, n_m))
        ex, ey = self._bias + self.rng.normal(0.0, self._white, 2)
        if any(abs(t - o) < 1e-6 for o in st.outliers):
            th = float(self.course.at("theta_rad", s_m))
            ex, ey = ex - st.outlier_m * math.sin(th), ey + st.outlier_m * math.cos(th)
        # to_geodetic takes floats too (pymap3d); its annotation says arrays only.
        lat, lon, alt = self.course.to_geodetic(x + ex, y + ey, z)
        return GpsFix(self.t0_s + t, float(lat), float(lon), float(alt), st.gps_std_m)


def sensor_samples(course: Course, t_s: np.ndarray, s_m: np.ndarray, n_m: np.ndarray,
                   v_mps: np.ndarray, power_w: np.ndarray, rng: np.random.Generator,
                   settings: SensorSettings = SensorSettings(), t0_s: float = 0.0
                   ) -> list[Sample]:
    """All samples of a recorded true trajectory (arrays over `t_s`), in stamp order."""
    sensors = Sensors(course, settings, rng, t0_s)
    out: list[Sample] = []
    for k in range(len(t_s)):
        out += sensors.sample(float(t_s[k]), float(s_m[k]), float(n_m[k]), float(v_mps[k]),
                              float(power_w[k]))
    return out


def smart_recording(rec: Recording, seed: int, max_step: int = 7) -> Recording:
    """The records of a 1 Hz ride that a head unit on smart recording (many Garmin
    units' default) would have kept: one every 1 to `max_step` records, at random."""
    keep = np.cumsum(np.random.default_rng(seed).integers(1, max_step + 1, size=len(rec)))
    keep = keep[keep < len(rec)]
    return dataclasses.replace(rec, **{  # every array thinned alike
        f.name: getattr(rec, f.name)[keep] for f in dataclasses.fields(rec)
        if isinstance(getattr(rec, f.name), np.ndarray)})
