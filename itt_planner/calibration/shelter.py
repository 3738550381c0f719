"""Stretches where a ride paid far less air drag than its rider alone would: shelter.

A replay drives the model with the ride's power as if the rider were alone in the day's
steady wind. Where the rider sat in a group (drafting) or had a local tail wind the
one steady wind of the day cannot hold, the ride goes faster than that power carries a
solo rider, and the replay falls behind: no model term is wrong, the ride had help the
validation cannot see. Such stretches are found by the power balance with the
calibrated rider (`ride_inputs`' unexplained power, the power the ride got beyond the
model's E3 at the ride's own speed and power), not hidden: over consecutive windows of
`UNEXPLAINED_WINDOW_M`, a window is sheltered when the unexplained power exceeds both
`SHELTER_MIN_W` and `SHELTER_SHARE` of the model's own air drag at the ride's speed
(a rider on a wheel saves 25-50 % of it; a solo rider's windows scatter about 0 by
+-40-65 W on the clean rides), and a stretch is `SHELTER_MIN_M` or more of such windows
in a row. The air drag is E3's own: its drag term is linear in CdA, so the difference
of the model's dv/dt at CdA and at twice CdA is the drag per unit mass.

The replay is not changed by them (the model rides them solo); `physics_check` reports
the time the model lost in each and the figures outside them beside the whole ride's.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from itt_planner.calibration.ride_inputs import UNEXPLAINED_WINDOW_M, coasting_accel_mps2
from itt_planner.calibration.ride_on_course import RideOnCourse
from itt_planner.course.geometry import Course
from itt_planner.model.conditions import Conditions
from itt_planner.model.dynamics import SpatialModel
from itt_planner.model.rider import Rider
from itt_planner.units import MPS_TO_KMH

#: Share of the model's air drag the ride did not pay, above which a window is sheltered.
SHELTER_SHARE = 0.3
#: ... and the least unexplained power (W): on a descent the drag share alone is noisy.
SHELTER_MIN_W = 50.0
#: Shortest sheltered stretch reported (m): a single window is within a solo ride's scatter.
SHELTER_MIN_M = 1000.0
#: Share of a window's intervals the replay drives with the ride's power for it to count.
_COVERED = 0.8


@dataclass(frozen=True, eq=False)
class Shelter:
    """Sheltered stretches of a ride: `mask` per grid interval, one dict per stretch."""

    mask: np.ndarray
    stretches: list[dict[str, float]]

    def summary(self) -> dict[str, Any]:
        return {"sheltered_stretches": len(self.stretches),
                "sheltered_m": round(sum(st["length_m"] for st in self.stretches), 1),
                "sheltered": self.stretches}


def air_drag_w(model: SpatialModel, course: Course, rider: Rider, conditions: Conditions,
               s_m: np.ndarray, v_mps: np.ndarray) -> np.ndarray:
    """The model's air drag power (W) at speed `v_mps` at places `s_m` (E3, the wind of
    `conditions` along the road)."""
    doubled = dataclasses.replace(rider, drag_area_m2=2.0 * rider.drag_area_m2)
    a_once = coasting_accel_mps2(model, course, rider, conditions, s_m, v_mps)
    a_twice = coasting_accel_mps2(model, course, doubled, conditions, s_m, v_mps)
    return np.asarray(rider.mass_kg * v_mps * (a_once - a_twice))


def find_shelter(model: SpatialModel, course: Course, rider: Rider, ride: RideOnCourse,
                 conditions: Conditions, unexplained_w: np.ndarray) -> Shelter:
    """The sheltered stretches of `ride` (module docstring), from `unexplained_w` per
    interval (NaN where the replay does not drive with the ride's power)."""
    s, ds = ride.s_m, np.diff(ride.s_m)
    v_mid = np.maximum(0.5 * (ride.v_mps[1:] + ride.v_mps[:-1]), 0.5)
    drag = air_drag_w(model, course, rider, conditions, 0.5 * (s[1:] + s[:-1]), v_mid)
    n = max(round(UNEXPLAINED_WINDOW_M / float(np.mean(ds))), 1)
    windows = []  # (first interval, unexplained W, drag W), sheltered windows only
    for i in range(0, len(ds) - n + 1, n):
        ok = np.isfinite(unexplained_w[i:i + n])
        if ok.mean() < _COVERED:
            continue
        dt = (ds[i:i + n] / v_mid[i:i + n])[ok]
        u = float(np.sum(unexplained_w[i:i + n][ok] * dt) / dt.sum())
        d = float(np.sum(drag[i:i + n][ok] * dt) / dt.sum())
        if u > SHELTER_MIN_W and u > SHELTER_SHARE * d:
            windows.append((i, u, d))
    mask = np.zeros(len(ds), bool)
    stretches = []
    for run in _consecutive(windows, n):
        i0, i1 = run[0][0], run[-1][0] + n
        if s[i1] - s[i0] < SHELTER_MIN_M:
            continue
        mask[i0:i1] = True
        dt = ds[i0:i1] / v_mid[i0:i1]
        u = float(np.mean([w[1] for w in run]))
        stretches.append({
            "from_m": round(float(s[i0]), 1), "length_m": round(float(s[i1] - s[i0]), 1),
            "ride_s": round(float(ride.t_moving_s[i1] - ride.t_moving_s[i0]), 1),
            "ride_kmh": round(MPS_TO_KMH * float(ds[i0:i1].sum() / dt.sum()), 1),
            "ride_power_w": round(float(np.sum(0.5 * (ride.power_w[i0:i1] + ride.power_w[
                i0 + 1:i1 + 1]) * dt) / dt.sum()), 0),
            "unexplained_w": round(u, 0),
            "drag_share_unpaid": round(u / float(np.mean([w[2] for w in run])), 2)})
    return Shelter(mask, stretches)


def _consecutive(windows: list[tuple[int, float, float]], n: int
                 ) -> list[list[tuple[int, float, float]]]:
    """Runs of windows that follow each other (first intervals `n` apart)."""
    runs: list[list[tuple[int, float, float]]] = []
    for w in windows:
        if runs and w[0] == runs[-1][-1][0] + n:
            runs[-1].append(w)
        else:
            runs.append([w])
    return runs
