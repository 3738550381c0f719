"""Closed-loop virtual rider: the 3D model integrated in time, sensors, scenarios.

`simulate_ride` rides a course with a simulated rider whose truth (critical power, wind,
behaviour) may differ from what the planner believes. The rider follows advice (target
power with a lag and noise, the advised line with a path-following controller); the
sensors emit stamped `GpsFix` (1 Hz, 3 m noise), `WheelSpeed` and `PowerReading` samples;
the pacing engine turns them into advice. The dynamics are B's 3D model
(`model.build_3d`, E1-E9) converted from the spatial to the time domain
(`dx/dt = (dx/ds) / (dt/ds)`), so the simulator and the planner share one set of
equations.

This module also holds `hairpin_course`, a short synthetic technical course (a hairpin,
a road crossing itself, an S-bend) used by the closed-loop tests and the CLI's quick
runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from itt_planner.course import Course, GeoOrigin
from itt_planner.samples import GpsFix, PowerReading, Sample, WheelSpeed


# ---- a short technical test course ---------------------------------------------------------
#: (length m, signed radius m: + left, - right, 0 straight, grade) of `hairpin_course`.
_HAIRPIN_SEGMENTS = (
    (500.0, 0.0, 0.02),
    (1.5 * math.pi * 50.0, 50.0, 0.0),  # 270 deg left: the road then crosses itself
    (400.0, 0.0, -0.01),
    (0.5 * math.pi * 30.0, -30.0, 0.0),
    (300.0, 0.0, -0.03),
    (math.pi * 12.0, 12.0, 0.0),  # the hairpin
    (500.0, 0.0, 0.01),
    (0.25 * math.pi * 40.0, -40.0, 0.0),  # S-bend
    (0.25 * math.pi * 40.0, 40.0, 0.0),
    (600.0, 0.0, 0.0),
)


def hairpin_course(ds_m: float = 1.0) -> Course:
    """A ~3 km synthetic course: climb, a 270 deg bend whose exit crosses the first
    straight, a 12 m hairpin, an S-bend. Curvature is smoothed over ~10 m (a real road
    has transition curves)."""
    kappa_parts, grade_parts = [], []
    for length, radius, grade in _HAIRPIN_SEGMENTS:
        n = int(round(length / ds_m))
        kappa_parts.append(np.full(n, 0.0 if radius == 0 else 1.0 / radius))
        grade_parts.append(np.full(n, grade))
    kappa = np.concatenate(kappa_parts)
    kernel = np.ones(int(10 / ds_m)) / int(10 / ds_m)
    kappa = np.convolve(kappa, kernel, mode="same")
    theta = np.concatenate([[0.0], np.cumsum(kappa) * ds_m])[:-1]
    x = np.concatenate([[0.0], np.cumsum(np.cos(theta)) * ds_m])[:-1]
    y = np.concatenate([[0.0], np.cumsum(np.sin(theta)) * ds_m])[:-1]
    z = 100.0 + np.concatenate([[0.0], np.cumsum(np.concatenate(grade_parts)) * ds_m])[:-1]
    return Course.from_centerline(
        "hairpin-test", x, y, z, origin=GeoOrigin(45.43, 10.99, 100.0), ds_m=ds_m,
        theta_rad=theta, kappa_per_m=kappa, source="itt_planner.simulate.hairpin_course",
        synthetic=True,
    )


# ---- sensors ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class SensorSettings:
    """Noise of the simulated sensors.

    GPS error is a slowly wandering bias (first-order Gauss-Markov, `gps_tau_s`) plus
    white noise: consecutive bike-GPS fixes are strongly correlated, which is what makes
    map matching hard. `gps_std_m` is the total horizontal 1-sigma per axis.

    Attributes:
        gps_period_s: fix interval (1 Hz).
        wheel_scale: the wheel sensor's circumference error (1.01 = reads 1 % fast).
        dropouts: (start stamp, duration) intervals without GPS.
        outliers: stamps at which the fix jumps `outlier_m` sideways.
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


def sensor_samples(course: Course, t_s: np.ndarray, s_m: np.ndarray, n_m: np.ndarray,
                   v_mps: np.ndarray, power_w: np.ndarray, rng: np.random.Generator,
                   settings: SensorSettings = SensorSettings(), t0_s: float = 0.0
                   ) -> list[Sample]:
    """Stamped GPS, wheel-speed and power samples of a true trajectory, sorted by stamp.

    The truth is interpolated at each sensor's own rate; `t0_s` offsets the stamps.
    Power is the pedalling power (braking is not measured by a power meter).
    """
    st = settings
    samples: list[tuple[float, int, Sample]] = []
    t_end = float(t_s[-1])
    # GPS: Gauss-Markov bias + white noise, per axis.
    white = st.gps_std_m * math.sqrt(st.gps_white_fraction)
    bias_std = st.gps_std_m * math.sqrt(1 - st.gps_white_fraction)
    a = math.exp(-st.gps_period_s / st.gps_tau_s)
    bias = rng.normal(0.0, bias_std, 2)
    for t in np.arange(0.0, t_end, st.gps_period_s):
        bias = a * bias + math.sqrt(1 - a * a) * rng.normal(0.0, bias_std, 2)
        if any(d0 <= t < d0 + dur for d0, dur in st.dropouts):
            continue
        s, n = np.interp(t, t_s, s_m), np.interp(t, t_s, n_m)
        x, y, z = course.enu_at(s, n)
        ex, ey = bias + rng.normal(0.0, white, 2)
        if any(abs(t - o) < 1e-9 for o in st.outliers):
            th = float(course.at("theta_rad", s))
            ex, ey = ex - st.outlier_m * math.sin(th), ey + st.outlier_m * math.cos(th)
        lat, lon, alt = course.to_geodetic(float(x) + ex, float(y) + ey, float(z))
        samples.append((t0_s + t, 0, GpsFix(t0_s + t, float(lat), float(lon), float(alt),
                                            st.gps_std_m)))
    for t in np.arange(0.0, t_end, st.speed_period_s):
        v = float(np.interp(t, t_s, v_mps)) * st.wheel_scale + rng.normal(0.0, st.speed_std_mps)
        samples.append((t0_s + t, 1, WheelSpeed(t0_s + t, max(v, 0.0))))
    for t in np.arange(0.0, t_end, st.power_period_s):
        p = max(float(np.interp(t, t_s, power_w)), 0.0)
        p = max(p + rng.normal(0.0, st.power_std_w), 0.0) if p > 0 else 0.0
        samples.append((t0_s + t, 2, PowerReading(t0_s + t, p)))
    samples.sort(key=lambda item: (item[0], item[1]))
    return [item[2] for item in samples]
