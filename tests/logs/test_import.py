"""Ride import: every real ride becomes a log whose counts and times match the file."""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path
from typing import Any

import fitdecode
import numpy as np
import pytest
from support.mcap_readers import check_all_readers, rerun_value
from typer.testing import CliRunner

from itt_planner.cli import app
from itt_planner.course.track_files import file_sha256, read_recording
from itt_planner.errors import RideLogError
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed
from itt_planner.logs.ride_import import (
    ImportSummary,
    count_gps_jumps,
    find_pauses,
    import_ride,
    ridden_gaps,
)
from itt_planner.logs.ridelog import RideLogReader
from itt_planner.logs.ridelog_writer import RideMetadata

RIDES = ["edge1000_ardennes_2019.fit", "edge810_vector_stjohns_2013.fit",
         "elemnt_shanghai_2019_stopgo.fit", "sauerland_2025.fit", "zwift_bologna_tt_virtual.tcx"]


def source_counts(path: Path) -> dict[str, Any]:
    """Records, stamps and per-field counts, parsed here without the project's reader."""
    times, pos, speed, power = [], 0, 0, 0
    with_data = []  # stamps of records that carry a position, a speed or a power
    if path.suffix == ".fit":
        with fitdecode.FitReader(str(path)) as fit:
            for frame in fit:
                if frame.frame_type != fitdecode.FIT_FRAME_DATA or frame.name != "record":
                    continue
                v = {f.name: f.value for f in frame.fields}
                times.append(v["timestamp"].timestamp())
                has = (v.get("position_lat") is not None and v.get("position_long") is not None,
                       v.get("enhanced_speed", v.get("speed")) is not None
                       or v.get("speed") is not None,
                       v.get("power") is not None)
                pos, speed, power = pos + has[0], speed + has[1], power + has[2]
                if any(has):
                    with_data.append(times[-1])
    else:
        ns = {"t": "http://www.garmin.com/xmlschemas/TrainingCenterDatabase/v2"}
        for tp in ET.parse(path).getroot().iterfind(".//t:Trackpoint", ns):
            stamp = tp.findtext("t:Time", namespaces=ns)
            assert stamp is not None
            times.append(np.datetime64(stamp.rstrip("Z"))
                         .astype("datetime64[ms]").astype(float) / 1000)
            has = (tp.find("t:Position", ns) is not None,
                   any(e.tag.endswith("Speed") for e in tp.iter()),
                   any(e.tag.endswith("Watts") for e in tp.iter()))
            pos, speed, power = pos + has[0], speed + has[1], power + has[2]
            if any(has):
                with_data.append(times[-1])
    return {"records": len(times), "duration_s": max(times) - min(times),
            "data_span": (min(with_data), max(with_data)),
            "/itt/gps/fix": pos, "/itt/speed": speed, "/itt/power": power}


class Imports:
    """Each ride imported on first use (a test of an absent unlicensed ride skips alone)."""

    def __init__(self, data_file: Callable[[str], Path], out: Path) -> None:
        self.data_file, self.out = data_file, out
        self.done: dict[str, ImportSummary] = {}

    def __getitem__(self, name: str) -> ImportSummary:
        if name not in self.done:
            src = self.data_file(f"rides/{name}")
            self.done[name] = import_ride(src, self.out / f"{name}.mcap", rider="R")
        return self.done[name]


@pytest.fixture(scope="module")
def imported(data_file: Callable[[str], Path], tmp_path_factory: pytest.TempPathFactory
             ) -> Imports:
    return Imports(data_file, tmp_path_factory.mktemp("imports"))


@pytest.mark.parametrize("name", RIDES)
def test_every_ride_imports_with_matching_counts(name: str, imported: Imports,
                                                 data_file: Callable[[str], Path]) -> None:
    summary = imported[name]
    src = data_file(f"rides/{name}")
    want = source_counts(src)
    assert summary.records == want["records"]
    assert summary.duration_s == pytest.approx(want["duration_s"], abs=1e-3)
    assert summary.topics == {t: want[t] for t in ("/itt/gps/fix", "/itt/speed", "/itt/power")}
    assert summary.records_without_position == want["records"] - want["/itt/gps/fix"]

    reader = RideLogReader(summary.output)
    entries = list(reader)
    assert reader.errors == [] and reader.warnings == []
    meta = dict(reader.metadata["itt_ride"])
    temperature = meta.pop("air_temperature_c", None)
    assert meta == {"source": name, "sha256": file_sha256(src), "device": summary.device,
                    "rider": "R"}
    # The day's air: the median of the records' temperatures, when the file has them.
    recorded = read_recording(src).temperature_c
    if recorded is None or not np.isfinite(recorded).any():
        assert temperature is None
        assert math.isnan(summary.air_temperature_c)
    else:
        assert float(temperature or "nan") == pytest.approx(np.nanmedian(recorded), abs=0.05)
        assert RideMetadata.from_record(reader.metadata["itt_ride"]).air_temperature_c \
            == summary.air_temperature_c
    counts = {t: sum(1 for e in entries if e[0] == t) for t in summary.topics}
    assert counts == summary.topics
    stamps = [s for _, s, _ in entries]
    assert stamps == sorted(stamps)
    assert (stamps[0], stamps[-1]) == pytest.approx(want["data_span"], abs=1e-6)
    kinds = {GpsFix: "/itt/gps/fix", WheelSpeed: "/itt/speed", PowerReading: "/itt/power"}
    assert all(isinstance(v, GpsFix | WheelSpeed | PowerReading) and kinds[type(v)] == t
               and v.stamp_s == pytest.approx(s) for t, s, v in entries)


def test_bad_ride_is_reported_not_cleaned(imported: Imports) -> None:
    """The data README's facts: sauerland has 8 pauses (longest 755 s), 7 GPS jumps, 3 spikes."""
    clean = imported["edge810_vector_stjohns_2013.fit"]
    assert (clean.pauses, clean.gps_jumps, clean.power_spikes) == ([], 0, 0)
    assert clean.duration_s == pytest.approx(78 * 60, abs=60)  # "1:18 h"
    s = imported["sauerland_2025.fit"]
    assert len(s.pauses) == 8 and max(p.duration_s for p in s.pauses) == 755.0
    assert (s.gps_jumps, s.power_spikes) == (7, 3)
    assert s.duration_s == pytest.approx(3.3 * 3600, abs=60)  # "3:18 h elapsed"
    # Kept as recorded: the spikes are in the log.
    powers = [v.power_w for _, _, v in RideLogReader(s.output) if isinstance(v, PowerReading)]
    assert sum(p > 1500 for p in powers) == 3
    zwift = imported["zwift_bologna_tt_virtual.tcx"]
    assert [p.duration_s for p in zwift.pauses] == [220.0]  # "one 220 s pause at the top"


def test_shanghai_keeps_speed_and_power_of_records_without_position(
        imported: Imports) -> None:
    s = imported["elemnt_shanghai_2019_stopgo.fit"]
    assert s.records_without_position > 100  # "~125 records without power or position"
    assert s.topics["/itt/speed"] > s.topics["/itt/gps/fix"]
    assert sum(p.duration_s for p in s.pauses) > 2.5 * 3600  # "2.8 h are gaps"


def test_imported_log_four_readers(imported: Imports, tmp_path: Path) -> None:
    s = imported["zwift_bologna_tt_virtual.tcx"]
    types = {"/itt/gps/fix": "sensor_msgs/msg/NavSatFix",
             "/itt/speed": "geometry_msgs/msg/TwistStamped",
             "/itt/power": "itt_msgs/msg/PowerStamped"}
    got = check_all_readers(s.output, {t: (types[t], n) for t, n in s.topics.items()}, tmp_path)
    ours = [v for _, _, v in RideLogReader(s.output) if isinstance(v, PowerReading)]
    for i in (0, 1000, len(ours) - 1):
        assert got["mcap_ros2"]["/itt/power"][i].power_w == ours[i].power_w
        assert got["rosbags"]["/itt/power"][i].power_w == ours[i].power_w
        assert rerun_value(got["rerun"]["/itt/power"][i])["power_w"] == ours[i].power_w
        fix = got["rosbags"]["/itt/gps/fix"][i]
        assert rerun_value(got["rerun"]["/itt/gps/fix"][i])["lat_lon"] == \
            pytest.approx([fix.latitude, fix.longitude])
        assert math.isnan(fix.position_covariance[0]) is False


def test_cli_import_json(data_file: Callable[[str], Path], tmp_path: Path) -> None:
    out = tmp_path / "z.mcap"
    src = data_file("rides/zwift_bologna_tt_virtual.tcx")
    result = CliRunner().invoke(app, ["import", str(src),
                                      "-o", str(out), "--rider", "A. Rider", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert {"output", "topics", "duration_s", "pauses", "gps_jumps", "power_spikes"} <= set(data)
    assert data["topics"] == {"/itt/gps/fix": 2072, "/itt/speed": 2072, "/itt/power": 2072}
    assert data["pauses"][0]["duration_s"] == 220.0 and out.is_file()

    bad = CliRunner().invoke(app, ["import", str(tmp_path / "none.fit"), "-o", str(out),
                                   "--json"])
    assert bad.exit_code == 1 and json.loads(bad.stdout)["type"] == "RideLogError"


def test_summary_helpers() -> None:
    t = np.array([0.0, 1, 2, 10, 11, 12, 12.5, 30])
    assert [(p.start_s, p.duration_s) for p in find_pauses(t)] == [(2.0, 8.0), (12.5, 17.5)]
    lat = np.array([45.0, 45.0001, 45.01, 45.01])  # 11 m, then 1.1 km in 1 s
    lon = np.full(4, 11.0)
    assert count_gps_jumps(lat, lon, np.array([0.0, 1, 2, 2])) == 1
    assert count_gps_jumps(lat[:1], lon[:1], t[:1]) == 0


def test_ride_without_times_is_refused(data_file: Callable[[str], Path], tmp_path: Path) -> None:
    course = data_file("courses/tokyo2020_olympic_itt_lap.csv")
    with pytest.raises(RideLogError, match=r"tokyo2020_olympic_itt_lap\.csv: .*no timestamps"):
        import_ride(course, tmp_path / "x.mcap")


def test_gaps_ridden_through_are_not_pauses(tmp_path: Path) -> None:
    """Smart recording (a record every 1-8 s while moving) is not a ride of pauses: a gap
    the rider rode through (<= 15 s, >= 1 m/s between the fixes) is a recording gap; a
    gap standing, or a long one, is a pause."""
    east_m = [0, 10, 20, 30, 90, 90.5, 91, 95, 100, 110]  # 6 s ridden, 6 s and 30 s standing
    stamps = [0, 1, 2, 3, 9, 15, 45, 46, 47, 48]
    gpx = tmp_path / "sparse.gpx"
    gpx.write_text(
        '<?xml version="1.0"?><gpx version="1.1" creator="t"><trk><trkseg>'
        + "".join(f'<trkpt lat="45.0" lon="{11 + x / 78_850:.8f}"><ele>100</ele>'
                  f"<time>2026-01-01T00:00:{t:02d}Z</time></trkpt>"
                  for x, t in zip(east_m, stamps, strict=True))
        + "</trkseg></trk></gpx>")
    s = import_ride(gpx, tmp_path / "sparse.mcap")
    assert [(p.start_s, p.duration_s) for p in s.recording_gaps] == [(3.0, 6.0)]
    assert [(p.start_s, p.duration_s) for p in s.pauses] == [(9.0, 6.0), (15.0, 30.0)]
    assert (s.as_dict()["recording_gaps"], s.as_dict()["recording_gap_longest_s"]) == (1, 6.0)
    # Without a fix at an end, the wheel speed at both ends says whether the rider moved.
    t = np.array([0.0, 5, 10, 80])
    steps = np.array([np.nan, np.nan, 400.0])
    assert ridden_gaps(t, steps, np.array([8.0, 9, 0.5, 9])).tolist() == [True, False, False]
    # An early smart recorder's 15-60 s gaps on a straight (a 2009 Garmin TCX in
    # stravalib's tests: 213 of them, each at 6.7-9.8 m/s) are ridden at 5 m/s or more; a
    # stop in one pulls its mean below that; beyond 60 s a gap is a pause at any speed.
    t = np.array([0.0, 25, 50, 120])
    assert ridden_gaps(t, np.array([200.0, 75.0, 700.0])).tolist() == [True, False, False]


def test_a_run_imports_with_a_warning(tmp_path: Path) -> None:
    """A run's file (a TCX `Sport="Running"`, as a Polar M400 writes) makes a log, with a
    warning in the JSON and on screen: the planner would pace a cyclist on it."""
    tcx = tmp_path / "run.tcx"
    tcx.write_text(
        '<?xml version="1.0"?><TrainingCenterDatabase xmlns="http://www.garmin.com/xmlschemas/'
        'TrainingCenterDatabase/v2"><Activities><Activity Sport="Running"><Id>2026-01-01T00:'
        '00:00Z</Id><Lap StartTime="2026-01-01T00:00:00Z"><Track>'
        + "".join(f"<Trackpoint><Time>2026-01-01T00:00:{i:02d}Z</Time><Position><Latitude"
                  f"Degrees>{45 + 3e-5 * i:.6f}</LatitudeDegrees><LongitudeDegrees>11.0"
                  "</LongitudeDegrees></Position></Trackpoint>" for i in range(10))
        + "</Track></Lap></Activity></Activities></TrainingCenterDatabase>")
    result = CliRunner().invoke(app, ["import", str(tcx), "-o", str(tmp_path / "r.mcap")])
    assert result.exit_code == 0, result.output
    assert "WARNING: the file is a 'Running' activity, not a ride" in result.stdout
    summary = import_ride(tcx, tmp_path / "r2.mcap").as_dict()
    assert summary["sport"] == "Running" and len(summary["warnings"]) == 1
