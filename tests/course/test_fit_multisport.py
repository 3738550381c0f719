"""A multisport FIT activity (a triathlon as a watch records it) is read as its bike leg.

The files are written here with fit-tool (a FIT encoder): no multisport FIT is in the
corpus, and the format is binary.
"""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import pytest
from fit_tool.fit_file_builder import FitFileBuilder
from fit_tool.profile.messages.file_id_message import FileIdMessage
from fit_tool.profile.messages.record_message import RecordMessage
from fit_tool.profile.messages.session_message import SessionMessage
from fit_tool.profile.profile_type import FileType, Manufacturer, Sport

from itt_planner.course.track_files import read_recording
from itt_planner.errors import CourseError

_T0_MS = datetime(2024, 6, 1, 7, 0, tzinfo=UTC).timestamp() * 1000


def _activity(path: Path, legs: list[tuple[Sport, int, bool]]) -> Path:
    """A FIT activity of `legs` (sport, seconds at 1 Hz, with GPS positions or not), each
    closed by its session message as watches write them; the bike rides at 250 W."""
    builder = FitFileBuilder(auto_define=True, min_string_size=50)
    file_id = FileIdMessage()
    file_id.type = FileType.ACTIVITY
    file_id.manufacturer = Manufacturer.GARMIN.value
    file_id.product = 0
    file_id.time_created = round(_T0_MS)
    builder.add(file_id)
    t = 0
    for sport, seconds, gps in legs:
        start = t
        for _ in range(seconds):
            record = RecordMessage()
            record.timestamp = round(_T0_MS + 1000 * t)
            if gps:
                record.position_lat = 45.0 + 1e-4 * t
                record.position_long = 7.0
                record.altitude = 200.0
            if sport == Sport.CYCLING:
                record.power = 250
                record.speed = 11.0
            builder.add(record)
            t += 1
        session = SessionMessage()
        session.sport = sport
        session.start_time = round(_T0_MS + 1000 * start)
        session.timestamp = round(_T0_MS + 1000 * (t - 1))
        session.total_elapsed_time = t - 1 - start
        builder.add(session)
    builder.build().to_file(str(path))
    return path


def test_a_triathlon_fit_gives_its_bike_leg(tmp_path: Path) -> None:
    """The swim, the transitions and the run were read as part of the ride (one stream
    of records): only the cycling session's records are."""
    path = _activity(tmp_path / "triathlon.fit", [
        (Sport.SWIMMING, 60, False), (Sport.TRANSITION, 20, True), (Sport.CYCLING, 120, True),
        (Sport.TRANSITION, 15, True), (Sport.RUNNING, 60, True)])
    rec = read_recording(path)
    assert len(rec) == 120 and rec.sport == "cycling"
    assert rec.power_w is not None and (rec.power_w == 250).all()
    assert rec.time_s is not None and rec.time_s[0] == pytest.approx(_T0_MS / 1000 + 80)


def test_a_ride_in_sessions_of_one_sport_keeps_every_record(tmp_path: Path) -> None:
    path = _activity(tmp_path / "ride.fit", [(Sport.CYCLING, 50, True), (Sport.CYCLING, 40, True)])
    rec = read_recording(path)
    assert len(rec) == 90 and rec.sport == "cycling"


def test_a_multisport_fit_without_a_ride_names_its_legs(tmp_path: Path) -> None:
    path = _activity(tmp_path / "aquathlon.fit", [(Sport.SWIMMING, 30, False),
                                                 (Sport.RUNNING, 40, True)])
    with pytest.raises(CourseError, match=r"aquathlon\.fit: a multisport activity without a "
                       r"cycling leg with GPS positions \(swimming: 30 records, 0 with a "
                       r"position; running: 40 records, 40 with a position\)"):
        read_recording(path)
