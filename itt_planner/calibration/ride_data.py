"""A recorded ride as the calibration estimators see it: clean 1 Hz series, or a refusal.

`prepare_ride` turns a `track_files.Recording` into a `RideSeries`: time-ordered samples
with speed (the device's, else derived from GPS), power, altitude, travelled distance and
air density (from altitude and temperature), split into stretches where the recording
is continuous. It refuses, with a `CalibrationError` naming the file and the reason, a
ride without stamps, power, altitude or movement, or one too short to fit anything. A ride
with stamps and power but no altitude or no speed (an indoor trainer's: no GPS) is
refused by `MissingChannelError`; `prepare_power` makes its power alone a `PowerSeries`,
which the power-duration curve takes (a CP test is often ridden indoors).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import cast

import numpy as np

from itt_planner.course.fit_records import fit_messages
from itt_planner.course.track_files import Recording, track_bytes, track_format
from itt_planner.errors import IttError
from itt_planner.logs.ride_import import (
    MOVING_MPS,
    PAUSE_MIN_S,
    POWER_SPIKE_W,
    fix_steps_m,
    ridden_gaps,
)
from itt_planner.model.conditions import DEFAULT_TEMPERATURE_C, air_density_kgpm3

#: Shortest moving time any estimator accepts (s).
MIN_MOVING_S = 600.0


class CalibrationError(IttError):
    """A ride cannot be calibrated or validated; the message names the file and why."""


class MissingChannelError(CalibrationError):
    """A ride has stamps and power but no altitude, or neither speed nor positions: the
    power balance cannot use it; its power alone can (`prepare_power`)."""


@dataclass(frozen=True, eq=False)
class RideSeries:
    """A ride's samples in time order (NaN-free where the estimators need it).

    Attributes:
        t_s: seconds since the first sample.
        v_mps: speed (device wheel/GPS speed, else from consecutive fixes).
        power_w: crank/hub power, 0 where missing.
        ele_m: altitude, interpolated over missing samples.
        dist_m: distance travelled, integrated from `v_mps`.
        rho_kgpm3: air density per sample.
        block: index of the continuous stretch each sample belongs to (a gap longer
            than `PAUSE_MIN_S` starts a new one).
        lat_deg, lon_deg: position (NaN where the record has none).
        gps_speed_mps: speed from consecutive fixes (NaN across gaps), the raw-GPS
            reference for the noise floor.
        speed_source: "device" or "gps".
        temperature_c: the mean temperature used for the air density.
        filled_s: samples interpolated at 1 s between sparse records
            (`ridden_gaps`); 0 for a 1 Hz record.
    """

    source: str
    t_s: np.ndarray
    v_mps: np.ndarray
    power_w: np.ndarray
    ele_m: np.ndarray
    dist_m: np.ndarray
    rho_kgpm3: np.ndarray
    block: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    gps_speed_mps: np.ndarray
    speed_source: str
    temperature_c: float
    filled_s: int = 0

    def __len__(self) -> int:
        return len(self.t_s)

    @property
    def moving_time_s(self) -> float:
        dt = np.diff(self.t_s)
        same = np.diff(self.block) == 0
        return float(np.sum(dt[same & (self.v_mps[1:] > MOVING_MPS)]))


@dataclass(frozen=True, eq=False)
class PowerSeries:
    """A ride's power alone (`prepare_power`), for the power-duration curve.

    Attributes:
        t_s, power_w, block: as `RideSeries`'s.
        why: why the ride's other channels are not used.
    """

    source: str
    t_s: np.ndarray
    power_w: np.ndarray
    block: np.ndarray
    why: str

    @property
    def moving_time_s(self) -> float:
        """Time pedalled (power above 0) within the continuous stretches."""
        dt = np.diff(self.t_s)
        return float(np.sum(dt[(np.diff(self.block) == 0) & (self.power_w[1:] > 0)]))


def _fit_messages(path: Path, message: str) -> list[dict[str, object]]:
    """The fields of every `message` data message of a FIT file (gzipped or not); [] for
    another format or a missing file (these are extras read beside `read_recording`)."""
    if track_format(path) != ".fit" or not path.is_file():
        return []
    return fit_messages(track_bytes(path), (message,))[message]


def record_setup(path: Path) -> str | None:
    """The bike profile a FIT file names (`bike_profile.name`, e.g. "TT bike"), when it
    names exactly one; None otherwise (most files name none)."""
    names = {str(r["name"]).strip() for r in _fit_messages(path, "bike_profile") if r.get("name")}
    return names.pop() if len(names) == 1 else None


def gps_speed_mps(lat_deg: np.ndarray, lon_deg: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """Speed of each sample from the great-circle step to the previous fix (NaN at gaps)."""
    step = fix_steps_m(lat_deg, lon_deg)
    dt = np.diff(t_s)
    with np.errstate(divide="ignore", invalid="ignore"):
        speed = np.where((dt > 0) & (dt <= PAUSE_MIN_S), step / dt, np.nan)
    return np.concatenate([[np.nan], speed])


def fill_sparse_records(rec: Recording) -> tuple[Recording, int]:
    """The record with the gaps the rider rode through (`ridden_gaps`: smart recording,
    missed fixes) filled at 1 s, linearly, and the number of samples added: the
    estimators' windows and smoothing are written for 1 Hz. Stamps must be finite, sorted
    and distinct."""
    assert rec.time_s is not None
    t = rec.time_s
    fill = np.flatnonzero(ridden_gaps(t, fix_steps_m(rec.lat_deg, rec.lon_deg), rec.speed_mps))
    if not len(fill):
        return rec, 0
    added = np.concatenate([np.arange(t[i] + 1.0, t[i + 1] - 0.5, 1.0) for i in fill])
    grid = np.sort(np.concatenate([t, added]))

    def on_grid(values: np.ndarray) -> np.ndarray:
        # NaN at either end of a gap leaves its filled samples NaN (missing, as before).
        return cast(np.ndarray, np.interp(grid, t, values))

    def maybe(values: np.ndarray | None) -> np.ndarray | None:
        return None if values is None else on_grid(values)

    filled = dataclasses.replace(
        rec, lat_deg=on_grid(rec.lat_deg), lon_deg=on_grid(rec.lon_deg),
        ele_m=on_grid(rec.ele_m), time_s=grid, speed_mps=maybe(rec.speed_mps),
        power_w=maybe(rec.power_w), cadence_rpm=maybe(rec.cadence_rpm),
        temperature_c=maybe(rec.temperature_c))
    return filled, len(added)


def prepare_ride(rec: Recording, *, temperature_c: float | None = None,
                 min_moving_s: float = MIN_MOVING_S) -> RideSeries:
    """The ride's series for the estimators.

    Temperature: `temperature_c` if given, else the records' median, else 15 C.

    Raises:
        CalibrationError: no timestamps, no power, no altitude, no speed or position,
            or less than `min_moving_s` of moving time (the message says which).
    """
    where = str(rec.path)
    order = _time_order(rec)
    ele_all = np.asarray(rec.ele_m, float)
    if np.sum(np.isfinite(ele_all)) < 2 or np.nanmax(ele_all) - np.nanmin(ele_all) <= 0.0:
        raise MissingChannelError(f"{where}: no elevation in the record; the power balance "
                                  "needs the climbing work")
    assert rec.time_s is not None
    assert rec.power_w is not None
    rec, filled = fill_sparse_records(dataclasses.replace(
        rec, lat_deg=rec.lat_deg[order], lon_deg=rec.lon_deg[order], ele_m=ele_all[order],
        time_s=rec.time_s[order], speed_mps=_take(rec.speed_mps, order),
        power_w=rec.power_w[order], cadence_rpm=_take(rec.cadence_rpm, order),
        temperature_c=_take(rec.temperature_c, order)))
    assert rec.time_s is not None
    assert rec.power_w is not None
    t_abs, lat, lon = rec.time_s, rec.lat_deg, rec.lon_deg
    gps_v = gps_speed_mps(lat, lon, t_abs)
    if rec.speed_mps is not None and np.sum(np.isfinite(rec.speed_mps)) > len(rec) // 2:
        speed, source = rec.speed_mps, "device"
    elif np.sum(np.isfinite(gps_v)) > len(rec) // 2:
        speed, source = gps_v, "gps"
    else:
        raise MissingChannelError(f"{where}: neither a speed sensor nor GPS positions; "
                                  "no speed to fit against")
    speed = _fill(np.asarray(speed, float))
    power = _clean_power(rec.power_w)
    ele = _fill(np.asarray(rec.ele_m, float))
    t = t_abs - t_abs[0]
    block = _blocks(t)
    dt = np.diff(t)
    same = np.diff(block) == 0
    step = np.where(same, 0.5 * (speed[1:] + speed[:-1]) * dt, 0.0)
    dist = np.concatenate([[0.0], np.cumsum(step)])
    if temperature_c is None:
        recorded = rec.air_temperature_c()
        temperature_c = recorded if math.isfinite(recorded) else DEFAULT_TEMPERATURE_C
    temp = float(temperature_c)
    series = RideSeries(
        source=where, t_s=t, v_mps=speed, power_w=power, ele_m=ele, dist_m=dist,
        rho_kgpm3=air_density_kgpm3(ele, temp), block=block, lat_deg=lat, lon_deg=lon,
        gps_speed_mps=gps_v, speed_source=source, temperature_c=temp, filled_s=filled,
    )
    if series.moving_time_s < min_moving_s:
        raise CalibrationError(f"{where}: too short: {series.moving_time_s:.0f} s of moving "
                               f"time, at least {min_moving_s:.0f} s needed")
    return series


def prepare_power(rec: Recording, why: str, *, min_moving_s: float = MIN_MOVING_S
                  ) -> PowerSeries:
    """The ride's power alone (`why`: what the power balance missed in it).

    Raises:
        CalibrationError: no timestamps, no power, or less than `min_moving_s` pedalled.
    """
    order = _time_order(rec)
    assert rec.time_s is not None
    assert rec.power_w is not None
    t = rec.time_s[order] - rec.time_s[order][0]
    series = PowerSeries(str(rec.path), t, _clean_power(rec.power_w[order]), _blocks(t), why)
    if series.moving_time_s < min_moving_s:
        raise CalibrationError(f"{rec.path}: too short: {series.moving_time_s:.0f} s pedalled, "
                               f"at least {min_moving_s:.0f} s needed")
    return series


def _time_order(rec: Recording) -> np.ndarray:
    """Indices of the records in time order, the first of each duplicate stamp (some head
    units write two records a second).

    Raises:
        CalibrationError: no timestamps, another sport than cycling, or no power (naming
            the file).
    """
    if rec.time_s is None or np.sum(np.isfinite(rec.time_s)) < 2:
        raise CalibrationError(f"{rec.path}: no timestamps; nothing can be fitted without time")
    if rec.other_sport:
        raise CalibrationError(f"{rec.path}: a {rec.sport!r} activity (the file says so), not a "
                               "ride: its power and speed are not a cyclist's")
    if rec.power_w is None or not np.any(np.nan_to_num(rec.power_w) > 0):
        raise CalibrationError(f"{rec.path}: no power readings; CdA, crr, CP and W' need power")
    ok = np.isfinite(rec.time_s)
    order = np.flatnonzero(ok)[np.argsort(rec.time_s[ok], kind="stable")]
    first: np.ndarray = order[np.concatenate([[True], np.diff(rec.time_s[order]) > 0])]
    return first


def _clean_power(power_w: np.ndarray) -> np.ndarray:
    """Power with missing readings and meter glitches (above any sprint: no information)
    read as 0."""
    power = np.nan_to_num(np.asarray(power_w, float), nan=0.0)
    return np.where(power > POWER_SPIKE_W, 0.0, power)


def _blocks(t_s: np.ndarray) -> np.ndarray:
    """Index of each sample's continuous stretch (a gap over `PAUSE_MIN_S` starts one)."""
    return np.concatenate([[0], np.cumsum(np.diff(t_s) > PAUSE_MIN_S)])


def _take(values: np.ndarray | None, index: np.ndarray) -> np.ndarray | None:
    return None if values is None else values[index]


def _fill(values: np.ndarray) -> np.ndarray:
    """Linear interpolation over NaN samples (constant beyond the ends)."""
    good = np.isfinite(values)
    if good.all():
        return values
    idx = np.arange(len(values))
    return cast(np.ndarray, np.interp(idx, idx[good], values[good]))


def smooth(values: np.ndarray, block: np.ndarray, window: int) -> np.ndarray:
    """Centred moving average over `window` samples that never mixes two blocks."""
    out = np.empty_like(values, dtype=float)
    half = window // 2
    for b in np.unique(block):
        idx = np.flatnonzero(block == b)
        seg = values[idx].astype(float)
        if len(seg) <= 2 or window <= 1:
            out[idx] = seg
            continue
        padded = np.concatenate([np.full(half, seg[0]), seg, np.full(half, seg[-1])])
        kernel = np.ones(2 * half + 1) / (2 * half + 1)
        out[idx] = np.convolve(padded, kernel, mode="valid")
    return out

