"""Read a FIT activity's records with fitdecode, keeping only a multisport file's bike leg.

A multisport activity (a triathlon or duathlon as a Garmin, Coros or Suunto watch records
it) is one FIT file with a `session` message per leg (swimming, transition, cycling,
running), each with its sport, start time and end, and the `record` messages of every leg
in one stream. The ride is the cycling leg: the records within the span of the cycling
session with the most GPS positions. A file whose sessions are all of one sport (a ride
saved in several sessions, or none) keeps all its records.
"""

from __future__ import annotations

import io
from collections.abc import Collection
from dataclasses import dataclass
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

from itt_planner.course.map_files import ride_leg

#: The sports (fitdecode's names of the FIT profile's `sport` values) that are a ride.
BIKE_SPORTS = frozenset({"cycling", "e_biking"})

Row = dict[str, Any]


@dataclass(frozen=True)
class FitActivity:
    """The records of a FIT activity (each a field name -> value mapping, fitdecode's units
    and names), the device that wrote it and its sport ("" when the file does not say)."""

    records: list[Row]
    device: str
    sport: str = ""


def fit_messages(data: bytes, names: Collection[str]) -> dict[str, list[Row]]:
    """The fields of every data message of `data` (a FIT file) named in `names`, by name,
    in file order (a CRC mismatch is a warning: many exports carry a wrong one).

    Raises:
        Exception: fitdecode's own errors on a corrupt file (the caller names the file).
    """
    import fitdecode  # noqa: PLC0415

    out: dict[str, list[Row]] = {name: [] for name in names}
    with fitdecode.FitReader(io.BytesIO(data), check_crc=fitdecode.CrcCheck.WARN) as reader:
        for frame in reader:
            if frame.frame_type == fitdecode.FIT_FRAME_DATA and frame.name in out:
                out[frame.name].append({f.name: f.value for f in frame.fields})
    return out


def read_fit_activity(path: Path, data: bytes) -> FitActivity:
    """The records of `data` (the FIT file `path`), only its bike leg when it is multisport.

    Raises:
        CourseError: a multisport file without a cycling leg with GPS positions.
        Exception: fitdecode's own errors on a corrupt file (the caller names the file).
    """
    messages = fit_messages(data, ("file_id", "record", "session"))
    rows, sessions = messages["record"], messages["session"]
    device = next((name for name in map(_device, messages["file_id"]) if name), "")
    sports = {str(s["sport"]) for s in sessions if s.get("sport") is not None}
    if len(sports) > 1:
        return FitActivity(_bike_leg(path, rows, sessions), device, "cycling")
    return FitActivity(rows, device, sports.pop() if sports else "")


def _device(file_id: Row) -> str:
    """The device a `file_id` message names ("" when none)."""
    return " ".join(str(file_id[k]) for k in ("manufacturer", "garmin_product", "product")
                    if file_id.get(k))


def _fixes(rows: list[Row]) -> int:
    return sum(r.get("position_lat") is not None and r.get("position_long") is not None
               for r in rows)


def _bike_leg(path: Path, rows: list[Row], sessions: list[Row]) -> list[Row]:
    """The rows of the cycling session with the most positions.

    Raises:
        CourseError: no cycling session has 3 positions or more (naming every leg).
    """
    legs = [(str(s.get("sport")), _rows_within(rows, s)) for s in sessions]
    return ride_leg(path, legs, is_ride=BIKE_SPORTS.__contains__, fixes=_fixes,
                    points="records", missing="activity without a cycling leg")


def _rows_within(rows: list[Row], session: Row) -> list[Row]:
    """The rows stamped within a session: from its start time to its end, the later of its
    own stamp and its start plus its elapsed time (either may be missing)."""
    start = session.get("start_time")
    if not isinstance(start, datetime):
        return []
    ends = [start + timedelta(seconds=float(session["total_elapsed_time"]))
            if session.get("total_elapsed_time") is not None else start]
    if isinstance(session.get("timestamp"), datetime):
        ends.append(session["timestamp"])
    end = max(ends)
    return [r for r in rows if isinstance(r.get("timestamp"), datetime)
            and start <= r["timestamp"] <= end]
