"""Import a recorded ride (FIT, GPX, TCX, CSV) into an MCAP ride log.

Every record becomes the input messages a live bike would have published at that time:
a `NavSatFix` when the record has a position, a wheel speed when it has a speed, a power
reading when it has power. Nothing is cleaned: gaps, power spikes and GPS jumps are kept
as recorded (the estimator deals with them, as it must live) and reported in the
summary, so a bad ride is recognised before it is replayed.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pymap3d.haversine import anglesep

from itt_msgs_py import DEFAULT_NAMESPACE, INPUT_TOPICS
from itt_planner.course.track_files import Recording, read_recording
from itt_planner.errors import CourseError, RideLogError
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed
from itt_planner.logs.ridelog_writer import RideLogWriter, RideMetadata

log = logging.getLogger(__name__)

#: A gap longer than this between records is a pause (auto-pause, stop, logger dropout);
#: 1 Hz loggers skip single samples all the time, five in a row are not noise.
PAUSE_MIN_S = 5.0
#: Consecutive fixes implying more than this speed (108 km/h) are a GPS jump.
GPS_JUMP_SPEED_MPS = 30.0
#: Power readings above this are spikes: beyond any rider's sprint, a meter glitch.
POWER_SPIKE_W = 1500.0
#: Mean Earth radius (IUGG): great-circle distance = radius x angular separation.
EARTH_RADIUS_M = 6_371_008.8
#: Slower than this is standing (walking pace is ~1.4 m/s): across a gap between two
#: records, and for calibration's moving samples (below it GPS wanders, nothing is fitted).
MOVING_MPS = 1.0
#: A gap of 2 s up to this long, across which the rider moved on at `MOVING_MPS` or more, is
#: the recorder's, not a stop: smart recording (many Garmin units' default) writes a record
#: every 1-8 s while moving, and 1 Hz loggers miss fixes. Longer gaps are pauses whatever
#: the distance (an auto-pause rolled through, a dropout in a tunnel), but:
RIDDEN_GAP_MAX_S = 15.0
#: a gap of up to this, across which the rider moved on at `LONG_GAP_MIN_MPS` (18 km/h) or
#: more, is the recorder's too: early smart-recording units (a 2009 Garmin TCX in
#: stravalib's tests: a record every 2-27 s, median 8 s) wrote one every 15-27 s on
#: straight roads, and its 213 such gaps were each ridden at 6.7-9.8 m/s; a stop of more
#: than a third of such a gap pulls the mean below it.
LONG_RIDDEN_GAP_MAX_S = 60.0
LONG_GAP_MIN_MPS = 5.0


@dataclass(frozen=True)
class Pause:
    """A gap between records: `start_s` after the first record, at POSIX `stamp_s`."""

    start_s: float
    stamp_s: float
    duration_s: float


@dataclass(frozen=True)
class ImportSummary:
    """What an import wrote and what it found odd in the recording."""

    output: Path
    source: Path
    sha256: str
    device: str
    records: int
    topics: dict[str, int]
    duration_s: float
    pauses: list[Pause] = field(default_factory=list)
    #: Gaps over `PAUSE_MIN_S` the rider rode through (`ridden_gaps`): not stops.
    recording_gaps: list[Pause] = field(default_factory=list)
    gps_jumps: int = 0
    power_spikes: int = 0
    records_without_position: int = 0
    #: The sport the file names ("" when none); another than cycling is a warning.
    sport: str = ""
    #: The median recorded air temperature (C; NaN when none): in the log's metadata.
    air_temperature_c: float = math.nan
    warnings: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        """The summary as plain JSON-able values (the CLI's `--json` object)."""
        return {
            "output": str(self.output), "source": str(self.source), "sha256": self.sha256,
            "device": self.device, "records": self.records, "topics": dict(self.topics),
            "duration_s": self.duration_s,
            "pauses": [{"start_s": p.start_s, "stamp_s": p.stamp_s, "duration_s": p.duration_s}
                       for p in self.pauses],
            "recording_gaps": len(self.recording_gaps),
            "recording_gap_longest_s": max((p.duration_s for p in self.recording_gaps),
                                           default=0.0),
            "gps_jumps": self.gps_jumps, "power_spikes": self.power_spikes,
            "records_without_position": self.records_without_position,
            "sport": self.sport, "warnings": list(self.warnings),
            "air_temperature_c": (self.air_temperature_c
                                  if math.isfinite(self.air_temperature_c) else None),
        }


def import_ride(source: str | Path, output: str | Path, *, rider: str = "",
                namespace: str = DEFAULT_NAMESPACE) -> ImportSummary:
    """Write the GPS, speed and power of a recorded ride as an MCAP ride log.

    Args:
        source: a ride with timestamps in any format `read_recording` reads (FIT, GPX,
            TCX, CSV, KML gx:Track, GeoJSON with stamps; gzipped or not).
        output: the `.mcap` file to write.
        rider: rider name for the log's metadata.
        namespace: ROS namespace of the topics.

    Raises:
        RideLogError: the ride cannot be read, has no timestamps, or the log cannot be
            written (names the file).
    """
    source = Path(source)
    try:
        rec = read_recording(source)
    except CourseError as err:
        raise RideLogError(str(err)) from None
    if rec.time_s is None:
        raise RideLogError(f"{source}: the recording has no timestamps; cannot make a ride log")
    keep = np.isfinite(rec.time_s)
    if not keep.all():
        log.warning("%s: %d records without a timestamp are dropped", source, (~keep).sum())
    # Stable sort: a log must be in time order to be replayed; ties keep the file's order.
    order = np.flatnonzero(keep)[np.argsort(rec.time_s[keep], kind="stable")]
    if len(order) == 0:
        raise RideLogError(f"{source}: no record has a timestamp")
    times = rec.time_s[order]

    temperature_c = rec.air_temperature_c(order)
    metadata = RideMetadata(source=source.name, sha256=rec.sha256, device=rec.device,
                            rider=rider, air_temperature_c=temperature_c)
    with RideLogWriter(output, metadata=metadata, namespace=namespace) as writer:
        for i in order:
            _write_record(writer, rec, int(i))
        counts = {t.name(namespace): writer.counts[t.name(namespace)] for t in INPUT_TOPICS}

    lat, lon = rec.lat_deg[order], rec.lon_deg[order]
    has_pos = np.isfinite(lat) & np.isfinite(lon)
    power = rec.power_w[order] if rec.power_w is not None else np.zeros(0)
    ridden = ridden_gaps(times, fix_steps_m(lat, lon),
                         None if rec.speed_mps is None else rec.speed_mps[order])
    return ImportSummary(
        output=Path(output), source=source, sha256=rec.sha256, device=rec.device,
        records=len(order), topics=counts, duration_s=float(times[-1] - times[0]),
        pauses=find_pauses(times, among=~ridden), recording_gaps=find_pauses(times, among=ridden),
        gps_jumps=count_gps_jumps(lat[has_pos], lon[has_pos], times[has_pos]),
        power_spikes=int(np.sum(power > POWER_SPIKE_W)),
        records_without_position=int(np.sum(~has_pos)), sport=rec.sport,
        air_temperature_c=temperature_c,
        warnings=[(f"the file is a {rec.sport!r} activity, not a ride: its speed and power "
                  "are not a cyclist's, and a replay's advice for them means nothing")
                  ] if rec.other_sport else [],
    )


def _write_record(writer: RideLogWriter, rec: Recording, i: int) -> None:
    """The messages of record `i`: only the fields it has."""
    assert rec.time_s is not None  # checked by the caller
    stamp = float(rec.time_s[i])
    if math.isfinite(rec.lat_deg[i]) and math.isfinite(rec.lon_deg[i]):
        writer.write_sample(GpsFix(stamp_s=stamp, lat_deg=float(rec.lat_deg[i]),
                                   lon_deg=float(rec.lon_deg[i]), alt_m=float(rec.ele_m[i])))
    if rec.speed_mps is not None and math.isfinite(rec.speed_mps[i]):
        writer.write_sample(WheelSpeed(stamp_s=stamp, speed_mps=float(rec.speed_mps[i])))
    if rec.power_w is not None and math.isfinite(rec.power_w[i]):
        cadence = float(rec.cadence_rpm[i]) if rec.cadence_rpm is not None else math.nan
        writer.write_sample(PowerReading(stamp_s=stamp, power_w=float(rec.power_w[i]),
                                         cadence_rpm=cadence))


def find_pauses(times_s: np.ndarray, min_gap_s: float = PAUSE_MIN_S, *,
                among: np.ndarray | None = None) -> list[Pause]:
    """Gaps of more than `min_gap_s` between consecutive records; with `among` (a mask
    per gap), only the gaps it marks."""
    gaps = np.diff(times_s)
    pick = (gaps > min_gap_s) & (True if among is None else among)
    return [Pause(start_s=float(times_s[i] - times_s[0]), stamp_s=float(times_s[i]),
                  duration_s=float(gaps[i]))
            for i in np.flatnonzero(pick)]


def fix_steps_m(lat_deg: np.ndarray, lon_deg: np.ndarray) -> np.ndarray:
    """Great-circle distance (m) from each fix to the next; NaN where either is missing."""
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    return np.asarray(EARTH_RADIUS_M * anglesep(lon[:-1], lat[:-1], lon[1:], lat[1:],
                                                deg=False), float)


def ridden_gaps(times_s: np.ndarray, steps_m: np.ndarray,
                speed_mps: np.ndarray | None = None) -> np.ndarray:
    """Per gap between consecutive records (sorted stamps), whether it is the recorder's:
    2 s to `RIDDEN_GAP_MAX_S` long with the rider `MOVING_MPS` or faster across it, or up
    to `LONG_RIDDEN_GAP_MAX_S` at `LONG_GAP_MIN_MPS`, by the fixes' `steps_m`, or where a
    fix is missing, by the wheel speed at both ends."""
    dt = np.diff(times_s)
    moved = steps_m
    if speed_mps is not None:
        moved = np.where(np.isfinite(moved), moved, np.fmin(speed_mps[:-1], speed_mps[1:]) * dt)
    moved = np.nan_to_num(moved)
    short = (dt >= 2.0) & (dt <= RIDDEN_GAP_MAX_S) & (moved >= MOVING_MPS * dt)
    long = ((dt > RIDDEN_GAP_MAX_S) & (dt <= LONG_RIDDEN_GAP_MAX_S)
            & (moved >= LONG_GAP_MIN_MPS * dt))
    return np.asarray(short | long)


def count_gps_jumps(lat_deg: np.ndarray, lon_deg: np.ndarray, times_s: np.ndarray,
                    max_speed_mps: float = GPS_JUMP_SPEED_MPS) -> int:
    """Consecutive fixes whose great-circle distance implies more than `max_speed_mps`.

    Fixes at the same stamp count as a jump when they are apart at all.
    """
    if len(lat_deg) < 2:
        return 0
    dist = fix_steps_m(lat_deg, lon_deg)
    dt = np.diff(times_s)
    with np.errstate(divide="ignore", invalid="ignore"):
        jumps = np.where(dt > 0, dist / np.where(dt > 0, dt, 1.0) > max_speed_mps, dist > 0)
    return int(np.sum(jumps))
