"""The data of the virtual-elevation fit: which intervals hold the balance, and the model.

`design` selects the stretches of a ride where the power balance holds (see `aero`) and
lays their per-interval terms end to end; `Design.residual` is the misfit, in metres of
elevation, of recorded altitude against the altitude the power explains for given
(mass, crr, CdA, wind per ride), each stretch with its own free offset (demeaned).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import cast

import numpy as np
import pymap3d

from itt_planner.calibration.ride_data import RideSeries
from itt_planner.model.conditions import GRAVITY_MPS2


@dataclass(frozen=True)
class Selection:
    """Which intervals the fit trusts (defaults: 1 Hz road rides).

    Attributes:
        min_power_w: intervals below this are coasting (braking unseen): excluded.
        min_speed_mps: below this speed noise dominates: excluded.
        max_accel_mps2: |dv/dt| above this is a sprint or braking: excluded.
        max_lateral_mps2: lateral acceleration (GPS yaw rate x speed) above this is a
            corner, usually with braking: excluded.
        guard_s: this many intervals around every excluded one are excluded too.
        min_stretch_s, max_stretch_s: stretches shorter are dropped, longer are split.
    """

    min_power_w: float = 40.0
    min_speed_mps: float = 3.0
    max_accel_mps2: float = 0.7
    max_lateral_mps2: float = 2.0
    guard_s: int = 3
    min_stretch_s: float = 30.0
    max_stretch_s: float = 240.0


def heading_and_lateral(ride: RideSeries) -> tuple[np.ndarray, np.ndarray]:
    """Heading (rad from East, ENU) and |lateral acceleration| per sample from the GPS
    track over +-2 samples (single 1 Hz fixes jitter by metres); NaN without positions."""
    n = len(ride)
    lat, lon = ride.lat_deg, ride.lon_deg
    good = np.flatnonzero(np.isfinite(lat) & np.isfinite(lon))
    if len(good) < 5:
        return np.full(n, np.nan), np.full(n, np.nan)
    x, y, _ = pymap3d.geodetic2enu(lat, lon, 0.0, lat[good[0]], lon[good[0]], 0.0)
    k = 2
    dx, dy = np.full(n, np.nan), np.full(n, np.nan)
    dx[k:-k], dy[k:-k] = x[2 * k:] - x[:-2 * k], y[2 * k:] - y[:-2 * k]
    moved = np.isfinite(dx) & (np.hypot(dx, dy) > 1.0)
    heading = np.where(moved, np.arctan2(dy, dx), np.nan)
    unwrapped = np.unwrap(np.nan_to_num(heading))
    lateral = np.abs(ride.v_mps * np.gradient(unwrapped, ride.t_s))
    return heading, np.where(moved, lateral, np.nan)


def usable_intervals(ride: RideSeries, sel: Selection, lateral: np.ndarray) -> np.ndarray:
    """Boolean per interval (i, i+1): the power balance without braking holds there."""
    dt = np.diff(ride.t_s)
    v, p = ride.v_mps, ride.power_w
    ok = (np.diff(ride.block) == 0) & (dt > 0) & (dt <= 2.0)
    ok &= (p[1:] >= sel.min_power_w) & (p[:-1] >= sel.min_power_w)
    ok &= (v[1:] >= sel.min_speed_mps) & (v[:-1] >= sel.min_speed_mps)
    with np.errstate(divide="ignore", invalid="ignore"):
        ok &= np.abs(np.diff(v) / dt) <= sel.max_accel_mps2
    ok &= ~(np.nan_to_num(lateral[1:], nan=0.0) > sel.max_lateral_mps2)
    bad = ~ok
    for shift in range(1, sel.guard_s + 1):  # the seconds next to a coast or corner
        bad[shift:] |= ~ok[:-shift]
        bad[:-shift] |= ~ok[shift:]
    return cast(np.ndarray, ~bad)


def stretches(ok: np.ndarray, sel: Selection) -> list[tuple[int, int]]:
    """Runs of usable intervals as sample ranges (start, end), split and filtered."""
    out: list[tuple[int, int]] = []
    edges = np.diff(np.concatenate([[0], ok.astype(int), [0]]))
    for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True):
        pieces = max(1, int(np.ceil((b - a) / sel.max_stretch_s)))
        bounds = np.linspace(a, b, pieces + 1).round().astype(int)
        out += [(int(lo), int(hi)) for lo, hi in itertools.pairwise(bounds)
                if hi - lo >= sel.min_stretch_s]
    return out


@dataclass(frozen=True, eq=False)
class Design:
    """Every stretch's intervals end to end (increment arrays) and samples (cumulative
    arrays start at 0 at each stretch start).

    Attributes:
        spans: (ride index, first sample, last sample) per stretch.
        ride_of: ride index per interval (for the wind of that ride).
        cum_at, cum_base: sample -> index into the cumulative sum of increments, and the
            index of its stretch's start (cumulative from the stretch start).
        group: stretch index per sample (the per-stretch offset).
    """

    spans: list[tuple[int, int, int]]
    n_rides: int
    work_j: np.ndarray
    dv2_m2ps2: np.ndarray
    dist_m: np.ndarray
    v_mps: np.ndarray
    rho_dt: np.ndarray
    cos_h: np.ndarray
    sin_h: np.ndarray
    ride_of: np.ndarray
    h_m: np.ndarray
    cum_at: np.ndarray
    cum_base: np.ndarray
    group: np.ndarray

    def _cum(self, inc: np.ndarray) -> np.ndarray:
        cs = np.concatenate([[0.0], np.cumsum(inc)])
        return cast(np.ndarray, cs[self.cum_at] - cs[self.cum_base])

    def virtual_height(self, mass_kg: float, crr: float, cda_m2: float | np.ndarray,
                       wind: np.ndarray) -> np.ndarray:
        """Height gained since each stretch start that the power explains (m); `cda_m2`
        one value, or one per interval (a CdA per setup)."""
        g = GRAVITY_MPS2
        u = wind[self.ride_of, 0] * self.cos_h + wind[self.ride_of, 1] * self.sin_h
        air = self.v_mps - u
        drag = 0.5 * cda_m2 * self.rho_dt * air * np.abs(air) * self.v_mps
        height = (self._cum(self.work_j) / (mass_kg * g) - self._cum(self.dv2_m2ps2) / (2 * g)
                  - crr * self._cum(self.dist_m) - self._cum(drag) / (mass_kg * g))
        return cast(np.ndarray, height)

    def residual(self, mass_kg: float, crr: float, cda_m2: float | np.ndarray, wind: np.ndarray,
                 weights: np.ndarray | None = None) -> np.ndarray:
        """Recorded minus virtual height, demeaned per stretch (weighted per stretch)."""
        r = self.h_m - self.virtual_height(mass_kg, crr, cda_m2, wind)
        count = np.bincount(self.group)
        r = r - (np.bincount(self.group, weights=r) / count)[self.group]
        return r if weights is None else cast(np.ndarray, r * np.sqrt(weights[self.group]))


def design(rides: list[RideSeries], sel: Selection, efficiency: float) -> Design:
    """The fit's data for `rides` (see `Design`)."""
    parts: dict[str, list[np.ndarray]] = {k: [] for k in (
        "work", "dv2", "dist", "v", "rho_dt", "cos", "sin", "ride", "h", "at", "base", "group")}
    spans: list[tuple[int, int, int]] = []
    offset = 0
    for k, ride in enumerate(rides):
        heading, lateral = heading_and_lateral(ride)
        # Without a GPS heading the wind cannot be projected: treat it as along-track.
        heading = np.nan_to_num(heading)
        for lo, hi in stretches(usable_intervals(ride, sel, lateral), sel):
            g = len(spans)
            spans.append((k, lo, hi))
            t, v = ride.t_s[lo:hi + 1], ride.v_mps[lo:hi + 1]
            dt = np.diff(t)
            p, rho = ride.power_w[lo:hi + 1], ride.rho_kgpm3[lo:hi + 1]
            h_mid = 0.5 * (heading[lo:hi] + heading[lo + 1:hi + 1])
            n = hi - lo
            parts["work"].append(efficiency * 0.5 * (p[1:] + p[:-1]) * dt)
            parts["dv2"].append(np.diff(v * v))
            parts["v"].append(0.5 * (v[1:] + v[:-1]))
            parts["dist"].append(parts["v"][-1] * dt)
            parts["rho_dt"].append(0.5 * (rho[1:] + rho[:-1]) * dt)
            parts["cos"].append(np.cos(h_mid))
            parts["sin"].append(np.sin(h_mid))
            parts["ride"].append(np.full(n, k))
            parts["h"].append(ride.ele_m[lo:hi + 1] - ride.ele_m[lo])
            parts["at"].append(offset + np.arange(n + 1))
            parts["base"].append(np.full(n + 1, offset))
            parts["group"].append(np.full(n + 1, g))
            offset += n
    cat = {k: (np.concatenate(v) if v else np.zeros(0)) for k, v in parts.items()}
    return Design(spans=spans, n_rides=len(rides), work_j=cat["work"], dv2_m2ps2=cat["dv2"],
                  dist_m=cat["dist"], v_mps=cat["v"], rho_dt=cat["rho_dt"], cos_h=cat["cos"],
                  sin_h=cat["sin"], ride_of=cat["ride"].astype(int), h_m=cat["h"],
                  cum_at=cat["at"].astype(int), cum_base=cat["base"].astype(int),
                  group=cat["group"].astype(int))
