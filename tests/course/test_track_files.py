"""Reading GPX/TCX/FIT/CSV into `Recording` (real files and small written ones)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from itt_planner.course.track_files import file_sha256, read_recording
from itt_planner.errors import CourseError


def test_fit_ride_has_positions_power_and_stamps(data_file: Callable[[str], Path]) -> None:
    rec = read_recording(data_file("rides/edge810_vector_stjohns_2013.fit"))
    assert len(rec) > 4000
    assert 47 < np.nanmean(rec.lat_deg) < 48 and -53 < np.nanmean(rec.lon_deg) < -52
    assert rec.time_s is not None and np.all(np.diff(rec.time_s) > 0)
    assert rec.power_w is not None and 200 < np.nanmean(rec.power_w) < 350
    assert rec.sha256 == file_sha256(rec.path)


def test_tcx(data_file: Callable[[str], Path]) -> None:
    tcx = read_recording(data_file("rides/zwift_bologna_tt_virtual.tcx"))
    assert len(tcx) > 1000 and tcx.power_w is not None


def test_csv(data_file: Callable[[str], Path]) -> None:
    csv = read_recording(data_file("courses/tokyo2020_olympic_itt_lap.csv"))
    assert len(csv) > 1900 and csv.time_s is None
    assert 35 < csv.lat_deg[0] < 36 and 138 < csv.lon_deg[0] < 139


def test_gpx_and_csv_with_header(tmp_path: Path) -> None:
    gpx = tmp_path / "t.gpx"
    gpx.write_text(
        '<?xml version="1.0"?><gpx version="1.1" creator="test"><trk><trkseg>'
        + "".join(f'<trkpt lat="45.{i:04d}" lon="11.0"><ele>{100 + i}</ele>'
                  f"<time>2026-01-01T00:00:{i:02d}Z</time></trkpt>" for i in range(5))
        + "</trkseg></trk></gpx>")
    rec = read_recording(gpx)
    assert len(rec) == 5 and rec.ele_m[-1] == 104 and rec.time_s is not None
    csv = tmp_path / "h.csv"
    csv.write_text("latitude,longitude,altitude\n45.0,11.0,10\n45.001,11.0,11\n")
    rec = read_recording(csv)
    assert rec.lat_deg.tolist() == [45.0, 45.001] and rec.ele_m.tolist() == [10, 11]


@pytest.mark.parametrize(("name", "text", "problem"), [
    ("missing.gpx", None, "no such file"),
    ("empty.tcx", "", "empty"),
    ("x.kml", "<kml/>", "unknown track format"),
    ("bad.csv", "lon,lat\nabc,45\n", "not a number"),
    ("bad.fit", "not a fit file", "not a valid FIT"),
])
def test_errors_name_the_file(tmp_path: Path, name: str, text: str | None, problem: str) -> None:
    path = tmp_path / name
    if text is not None:
        path.write_text(text)
    with pytest.raises(CourseError, match=problem) as info:
        read_recording(path)
    assert name in str(info.value)
