"""Reading GPX/TCX/FIT/CSV into `Recording` (real files and small written ones), and the
same as Strava's bulk export writes them (gzipped; XML after leading spaces)."""

from __future__ import annotations

import gzip
import math
import re
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest

from itt_planner.calibration import CalibrationError, calibrate
from itt_planner.course.loader import load_course
from itt_planner.course.track_files import file_sha256, read_recording, track_format
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


def test_gpx_extensions_power_speed_cadence_temperature(tmp_path: Path) -> None:
    """The sensor values GPX exports carry in extensions: Garmin's TrackPointExtension v2
    (speed, cadence, air temperature) and PowerExtension, Strava's plain <power>; a
    value that is not a number is missing, not a broken file."""
    garmin = ('<extensions><gpxtpx:TrackPointExtension><gpxtpx:atemp>{t}</gpxtpx:atemp>'
              '<gpxtpx:cad>{c}</gpxtpx:cad><gpxtpx:speed>{v}</gpxtpx:speed>'
              '</gpxtpx:TrackPointExtension><pwr:PowerInWatts>{p}</pwr:PowerInWatts>'
              '</extensions>')
    points = [garmin.format(t=21, c=90, v=11.5, p=310), garmin.format(t=23, c=92, v=12.0,
                                                                      p="n/a"),
              "<extensions><power>250</power></extensions>", ""]
    gpx = tmp_path / "sensors.gpx"
    gpx.write_text(
        '<?xml version="1.0"?><gpx version="1.1" creator="test" '
        'xmlns="http://www.topografix.com/GPX/1/1" '
        'xmlns:gpxtpx="http://www.garmin.com/xmlschemas/TrackPointExtension/v2" '
        'xmlns:pwr="http://www.garmin.com/xmlschemas/PowerExtension/v1"><trk><trkseg>'
        + "".join(f'<trkpt lat="45.{i:04d}" lon="11.0"><ele>100</ele>'
                  f"<time>2026-01-01T00:00:{i:02d}Z</time>{ext}</trkpt>"
                  for i, ext in enumerate(points))
        + "</trkseg></trk></gpx>")
    rec = read_recording(gpx)
    assert rec.power_w is not None and rec.speed_mps is not None
    assert rec.cadence_rpm is not None and rec.temperature_c is not None
    np.testing.assert_array_equal(rec.power_w, [310, np.nan, 250, np.nan])
    np.testing.assert_array_equal(rec.speed_mps, [11.5, 12.0, np.nan, np.nan])
    np.testing.assert_array_equal(rec.cadence_rpm, [90, 92, np.nan, np.nan])
    assert rec.air_temperature_c() == 22.0


def test_csv_ride_with_iso_times_and_sensor_columns(tmp_path: Path) -> None:
    """A ride exported as CSV (GoldenCheetah-like names): ISO 8601 times (UTC without a
    zone), power, speed in km/h, cadence, temperature; a bad time names line and field."""
    csv = tmp_path / "ride.csv"
    csv.write_text("timestamp,latitude,longitude,altitude,watts,kph,cad,temp\n"
                   "2026-01-01T10:00:00Z,45.0,11.0,100,250,36,90,21\n"
                   "2026-01-01T10:00:01,45.0001,11.0,100,,36.9,,21\n"
                   "2026-01-01T11:00:02+01:00,45.0002,11.0,101,260,37.8,92,23\n")
    rec = read_recording(csv)
    assert rec.time_s is not None and rec.speed_mps is not None and rec.power_w is not None
    start = datetime(2026, 1, 1, 10, tzinfo=UTC).timestamp()
    np.testing.assert_array_equal(rec.time_s - start, [0, 1, 2])
    np.testing.assert_allclose(rec.speed_mps, [10.0, 10.25, 10.5])
    np.testing.assert_array_equal(rec.power_w, [250, np.nan, 260])
    assert rec.cadence_rpm is not None and rec.cadence_rpm[2] == 92
    assert rec.air_temperature_c() == 21.0
    csv.write_text("time,lat,lon\n2026-01-01T10:00:00Z,45,11\nyesterday,45,11\n")
    with pytest.raises(CourseError, match=r"line 3: time 'yesterday' is not a number or an "
                                          "ISO 8601 time"):
        read_recording(csv)


@pytest.mark.parametrize(("name", "text", "problem"), [
    ("missing.gpx", None, "no such file"),
    ("empty.tcx", "", "empty"),
    ("x.shp", "shapes", "unknown track format"),
    ("bad.csv", "lon,lat\nabc,45\n", "not a number"),
    ("bad.fit", "not a fit file", "not a valid FIT"),
    ("bad.fit.gz", "not gzip data", "not a valid gzip file"),
    ("ride.gz", "", "unknown track format"),
])
def test_errors_name_the_file(tmp_path: Path, name: str, text: str | None, problem: str) -> None:
    path = tmp_path / name
    if text is not None:
        path.write_text(text)
    with pytest.raises(CourseError, match=problem) as info:
        read_recording(path)
    assert name in str(info.value)


def _strava_tcx(n: int) -> str:
    """A TCX activity as Strava exports it: ten spaces before the declaration, the
    extension in a default namespace, stamps without fractions; 1 Hz due north at 10 m/s."""
    points = "".join(
        f"<Trackpoint><Time>2026-05-01T10:00:{i % 60:02d}Z</Time><Position>"
        f"<LatitudeDegrees>{45 + i * 10 / 111_195:.7f}</LatitudeDegrees>"
        f"<LongitudeDegrees>11.0</LongitudeDegrees></Position>"
        f"<AltitudeMeters>{100 + 0.1 * i:.1f}</AltitudeMeters><Extensions><TPX "
        f'xmlns="http://www.garmin.com/xmlschemas/ActivityExtension/v2"><Speed>10.0</Speed>'
        f"<Watts>{250 + i}</Watts></TPX></Extensions></Trackpoint>" for i in range(n))
    return ("          <?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<TrainingCenterDatabase "
            'xmlns="http://www.garmin.com/xmlschemas/TrainingCenterDatabase/v2"><Activities>'
            '<Activity Sport="Biking"><Id>2026-05-01T10:00:00Z</Id>'
            '<Lap StartTime="2026-05-01T10:00:00Z"><Track>' + points
            + "</Track></Lap></Activity></Activities></TrainingCenterDatabase>")


def test_tcx_keeps_trackpoints_before_the_first_fix(tmp_path: Path) -> None:
    """A head unit that found no GPS for its first minute still logged power and speed:
    those trackpoints are read (tcxreader's default drops them; an Edge 705 file of
    GoldenCheetah's tests lost 1,378 of its 1,439 so, with a 198 s duration for 7,687 s)."""
    text = _strava_tcx(50)
    for i in range(10):  # the first 10 trackpoints without their fix
        start = text.index("<Position>", text.index(f":{i:02d}Z</Time>"))
        text = text[:start] + text[text.index("</Position>", start) + len("</Position>"):]
    path = tmp_path / "late_fix.tcx"
    path.write_text(text)
    rec = read_recording(path)
    assert len(rec) == 50 and rec.time_s is not None and rec.power_w is not None
    assert int(np.isnan(rec.lat_deg).sum()) == 10 and rec.power_w[0] == 250
    assert rec.time_s[-1] - rec.time_s[0] == 49


def test_strava_exports_leading_spaces_and_gzip(tmp_path: Path) -> None:
    # Strava's TCX (and some of its GPX) start with spaces before `<?xml`, which XML
    # forbids and ElementTree refuses; its bulk export gzips the files.
    plain = tmp_path / "1234.tcx"
    plain.write_text(_strava_tcx(50))
    packed = tmp_path / "1234.tcx.gz"
    packed.write_bytes(gzip.compress(plain.read_bytes()))
    for path in (plain, packed):
        rec = read_recording(path)
        assert len(rec) == 50 and rec.power_w is not None and rec.speed_mps is not None
        assert rec.power_w[-1] == 299 and rec.speed_mps[0] == 10.0
        assert rec.sha256 == file_sha256(path)
    gpx = tmp_path / "1234.gpx"
    gpx.write_bytes(b"\xef\xbb\xbf   " + (
        '<?xml version="1.0"?><gpx version="1.1" creator="StravaGPX"><trk><trkseg>'
        + "".join(f'<trkpt lat="45.{i:04d}" lon="11.0"><ele>{100 + i}</ele></trkpt>'
                  for i in range(5)) + "</trkseg></trk></gpx>").encode())
    assert len(read_recording(gpx)) == 5 and read_recording(gpx).device == "StravaGPX"


def test_a_gzipped_fit_is_the_fit(tmp_path: Path, data_file: Callable[[str], Path]) -> None:
    src = data_file("rides/edge810_vector_stjohns_2013.fit")
    packed = tmp_path / f"{src.name}.gz"
    packed.write_bytes(gzip.compress(src.read_bytes()))
    assert track_format(packed) == ".fit" and track_format(tmp_path / "a.b.gz") == ""
    a, b = read_recording(src), read_recording(packed)
    for name in ("lat_deg", "lon_deg", "ele_m", "time_s", "speed_mps", "power_w",
                 "temperature_c"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.device == b.device and b.sha256 == file_sha256(packed) != a.sha256
    assert math.isfinite(b.air_temperature_c())  # the head unit's, for the air density


def test_a_gzipped_route_loads_as_a_course(tmp_path: Path) -> None:
    # 2 km due east, a point every 20 m: `load_course` takes the .gpx.gz as a GPS track.
    gpx = ('<?xml version="1.0"?><gpx version="1.1" creator="t"><rte>'
           + "".join(f'<rtept lat="45.0" lon="{11 + i * 20 / 78_850:.7f}"><ele>100</ele>'
                     "</rtept>" for i in range(101)) + "</rte></gpx>")
    path = tmp_path / "route.gpx.gz"
    path.write_bytes(gzip.compress(gpx.encode()))
    course = load_course(path)
    assert course.name == "route" and 1950 < course.length_m < 2050


def test_a_multisport_tcx_gives_its_bike_leg(tmp_path: Path) -> None:
    """A triathlon's TCX (Garmin's `MultiSportSession`: FirstSport, NextSport...) was "no
    track points found" (tcxreader reads `Activities/Activity` only): its bike leg is the
    ride. Without a Biking activity with positions (a Forerunner 305's file of runs and
    indoor rides, GoldenCheetah's tests) the error names every activity."""
    ride = _strava_tcx(50).strip()
    head, body = ride.split("<Activities>")
    bike = body.split("</Activities>")[0]
    run = bike.replace('Sport="Biking"', 'Sport="Running"').replace("<Watts>", "<Watts>1")
    indoor = re.sub(r"<Position>.*?</Position>", "", bike)

    def session(*legs: str) -> str:
        sports = "".join(f"<{'FirstSport' if i == 0 else 'NextSport'}>{leg}"
                         f"</{'FirstSport' if i == 0 else 'NextSport'}>"
                         for i, leg in enumerate(legs))
        return (f"{head}<Activities><MultiSportSession>{sports}</MultiSportSession>"
                "</Activities></TrainingCenterDatabase>")

    path = tmp_path / "triathlon.tcx"
    path.write_text(session(run, bike, run))
    rec = read_recording(path)
    assert len(rec) == 50 and rec.power_w is not None and rec.power_w[0] == 250
    path.write_text(session(run, indoor))
    with pytest.raises(CourseError, match=r"triathlon\.tcx: a multisport session without a "
                       r"Biking activity with GPS positions \(Running: 50 trackpoints, 50 "
                       r"with a position; Biking: 50 trackpoints, 0 with a position\)"):
        read_recording(path)


def test_a_run_is_read_as_a_route_and_named(tmp_path: Path) -> None:
    """A run (a Polar M400's TCX in sweatpy's examples, `Sport="Running"`) was read as a
    ride without a word: its track is a course with a warning, and calibrate refuses its
    power (a running power meter's is no cyclist's). A ride's sport is kept as named,
    Strava's GPX code (`<type>1</type>`) too, and is no warning."""
    run = tmp_path / "run.tcx"
    run.write_text(_strava_tcx(700).replace('Sport="Biking"', 'Sport="Running"'))
    rec = read_recording(run)
    assert rec.sport == "Running" and rec.other_sport
    warnings = load_course(run).build["warnings"]
    assert "the file is a 'Running' activity, not a ride: its track is read as a course" \
        in warnings
    with pytest.raises(CalibrationError, match=r"run\.tcx: a 'Running' activity \(the file "
                       r"says so\), not a ride"):
        calibrate([run])
    ride = tmp_path / "ride.tcx"
    ride.write_text(_strava_tcx(50))
    assert read_recording(ride).sport == "Biking" and not read_recording(ride).other_sport
    gpx = tmp_path / "strava.gpx"
    gpx.write_text('<?xml version="1.0"?><gpx version="1.1" creator="StravaGPX" '
                   'xmlns="http://www.topografix.com/GPX/1/1"><trk><type>1</type><trkseg>'
                   + "".join(f'<trkpt lat="45.{i:04d}" lon="11.0"><ele>100</ele></trkpt>'
                             for i in range(5)) + "</trkseg></trk></gpx>")
    assert read_recording(gpx).sport == "1" and not read_recording(gpx).other_sport


def _pwx(samples: str, sport: str = "Bike") -> str:
    """A PWX file as IpBike writes it (GoldenCheetah's tests: `IpBike_902.pwx`)."""
    return ('<?xml version="1.0"?>\n<pwx xmlns="http://www.peaksware.com/PWX/1/0" '
            'version="1.0" creator="iforpowell.com/1.0" >\n<workout>\n'
            f"<sportType>{sport}</sportType>\n<time>2016-01-11T07:07:32</time>\n"
            '<summarydata><beginning>0</beginning><duration>3070</duration></summarydata>\n'
            f"{samples}</workout>\n</pwx>\n")


def test_pwx_workout(tmp_path: Path) -> None:
    """TrainingPeaks' PWX (WKO, GoldenCheetah and IpBike export it): samples stamped by
    their offset from the workout's start, with position, altitude, speed, power, cadence
    and temperature; a sample without a reading is missing there, not a broken file."""
    rows = "".join(
        f"<sample>\n<timeoffset>{i + 1}</timeoffset>\n<hr>111</hr>\n<spd>{8 + 0.01 * i}</spd>"
        f"\n<pwr>{200 + i}</pwr>\n<pwrright>0</pwrright>\n<cad>90</cad>\n<dist>{8 * i}</dist>"
        f"\n<lat>{46.08 + i * 8 / 111_195:.7f}</lat>\n<lon>14.5166</lon>\n"
        f"<alt>{300 + 0.05 * i}</alt>\n<temp>18.2</temp>\n</sample>\n" for i in range(400))
    path = tmp_path / "ride.pwx"
    path.write_text(_pwx(rows + "<sample><timeoffset>401</timeoffset></sample>\n"))
    rec = read_recording(path)
    assert len(rec) == 401 and rec.sport == "Bike" and not rec.other_sport
    assert rec.time_s is not None
    assert rec.time_s[0] == datetime(2016, 1, 11, 7, 7, 33, tzinfo=UTC).timestamp()
    assert rec.power_w is not None and rec.power_w[5] == 205 and np.isnan(rec.power_w[-1])
    assert rec.speed_mps is not None and rec.speed_mps[0] == 8.0
    assert rec.cadence_rpm is not None and rec.temperature_c is not None
    assert 3150 < load_course(path).length_m < 3250
    path.write_text(_pwx(rows, sport="Run"))
    assert read_recording(path).other_sport
    path.write_text(_pwx(""))
    with pytest.raises(CourseError, match=r"ride\.pwx: no samples in the PWX file"):
        read_recording(path)
    path.write_text("<?xml version='1.0'?><gpx/>")
    with pytest.raises(CourseError, match=r"ride\.pwx: not a PWX file \(its root is <gpx>\)"):
        read_recording(path)
