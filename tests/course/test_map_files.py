"""Routes from web maps (KML, KMZ, GeoJSON) read as the same GPX route would be: the real
St John's ride's first 12 minutes written in each format, with and without stamps."""

from __future__ import annotations

import json
import zipfile
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest

from itt_planner.course.loader import load_course
from itt_planner.course.track_files import Recording, read_recording
from itt_planner.errors import CourseError
from itt_planner.logs.ride_import import import_ride

#: The ride's first 720 records (12 min at 1 Hz, 4.8 km through its first corners).
POINTS = 720


@pytest.fixture(scope="module")
def ride(data_file: Callable[[str], Path]) -> Recording:
    return read_recording(data_file("rides/edge810_vector_stjohns_2013.fit"))


def _rows(ride: Recording) -> list[tuple[float, float, float, float]]:
    keep = np.flatnonzero(np.isfinite(ride.lat_deg))[:POINTS]
    assert ride.time_s is not None
    return [(float(ride.lon_deg[i]), float(ride.lat_deg[i]), float(ride.ele_m[i]),
             float(ride.time_s[i])) for i in keep]


def _iso(stamp: float) -> str:
    return datetime.fromtimestamp(stamp, UTC).isoformat().replace("+00:00", "Z")


def _write_formats(rows: list[tuple[float, float, float, float]], folder: Path) -> list[Path]:
    """The route as GPX, as My Maps' KML (a marker and the line in a folder), as KMZ, as
    Google Earth's gx:Track (stamped) and as a GeoJSON FeatureCollection (a marker, the
    line with togeojson's stamps)."""
    gpx = folder / "route.gpx"
    gpx.write_text('<?xml version="1.0"?><gpx version="1.1" creator="t"><trk><trkseg>' + "".join(
        f'<trkpt lat="{la}" lon="{lo}"><ele>{z}</ele><time>{_iso(t)}</time></trkpt>'
        for lo, la, z, t in rows) + "</trkseg></trk></gpx>")
    coords = " ".join(f"{lo},{la},{z}" for lo, la, z, _ in rows)
    kml_text = (
        '<?xml version="1.0" encoding="UTF-8"?><kml xmlns="http://www.opengis.net/kml/2.2">'
        "<Document><name>ITT</name><Folder><name>Layer 1</name><Placemark><name>Start</name>"
        f"<Point><coordinates>{rows[0][0]},{rows[0][1]},0</coordinates></Point></Placemark>"
        f"<Placemark><LineString><tessellate>1</tessellate><coordinates>{coords}</coordinates>"
        "</LineString></Placemark></Folder></Document></kml>")
    kml = folder / "route.kml"
    kml.write_text(kml_text)
    kmz = folder / "route.kmz"
    with zipfile.ZipFile(kmz, "w") as archive:
        archive.writestr("doc.kml", kml_text)
    track = folder / "track.kml"
    track.write_text(
        '<?xml version="1.0"?><kml xmlns="http://www.opengis.net/kml/2.2" '
        'xmlns:gx="http://www.google.com/kml/ext/2.2"><Document><Placemark><gx:Track>'
        + "".join(f"<when>{_iso(t)}</when>" for *_, t in rows)
        + "".join(f"<gx:coord>{lo} {la} {z}</gx:coord>" for lo, la, z, _ in rows)
        + "</gx:Track></Placemark></Document></kml>")
    geojson = folder / "route.geojson"
    geojson.write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {},
         "geometry": {"type": "Point", "coordinates": list(rows[0][:2])}},
        {"type": "Feature",
         "properties": {"coordinateProperties": {"times": [_iso(t) for *_, t in rows]}},
         "geometry": {"type": "LineString", "coordinates": [list(r[:3]) for r in rows]}}]}))
    return [gpx, kml, kmz, track, geojson]


def test_map_formats_read_as_the_gpx(tmp_path: Path, ride: Recording) -> None:
    rows = _rows(ride)
    gpx, *maps = _write_formats(rows, tmp_path)
    want = read_recording(gpx)
    for path in maps:
        got = read_recording(path)
        for name in ("lat_deg", "lon_deg", "ele_m"):
            np.testing.assert_allclose(getattr(got, name), getattr(want, name), atol=1e-9,
                                       err_msg=f"{path.name} {name}")
        stamped = path.name in ("track.kml", "route.geojson")
        assert (got.time_s is not None) == stamped, path.name
        if got.time_s is not None:
            np.testing.assert_allclose(got.time_s, [t for *_, t in rows], atol=1e-6)
    # The same course from each (the fit sees the same points).
    lengths = {p.name: load_course(p).length_m for p in (gpx, *maps)}
    assert max(lengths.values()) - min(lengths.values()) < 1e-6, lengths
    assert 4500 < lengths["route.gpx"] < 5200


def test_a_kml_track_carries_its_sensors(tmp_path: Path, ride: Recording) -> None:
    """Google Earth's gx:Track of a ride with its ExtendedData arrays: the ride's power,
    cadence and speed read as the FIT's, a value that is not a number as missing, an
    array of another length as absent; imported, the power is in the ride log."""
    keep = np.flatnonzero(np.isfinite(ride.lat_deg))[:POINTS]
    assert ride.time_s is not None and ride.power_w is not None
    assert ride.cadence_rpm is not None and ride.speed_mps is not None
    power = [f"{ride.power_w[i]:g}" for i in keep]
    power[5] = "n/a"

    def array(name: str, values: list[str]) -> str:
        return (f'<gx:SimpleArrayData name="{name}">'
                + "".join(f"<gx:value>{v}</gx:value>" for v in values) + "</gx:SimpleArrayData>")

    track = tmp_path / "ride.kml"
    track.write_text(
        '<?xml version="1.0"?><kml xmlns="http://www.opengis.net/kml/2.2" '
        'xmlns:gx="http://www.google.com/kml/ext/2.2"><Document><Placemark><gx:Track>'
        + "".join(f"<when>{_iso(ride.time_s[i])}</when>" for i in keep)
        + "".join(f"<gx:coord>{ride.lon_deg[i]} {ride.lat_deg[i]} {ride.ele_m[i]}</gx:coord>"
                  for i in keep)
        + '<ExtendedData><SchemaData schemaUrl="#s">' + array("power", power)
        + array("Cadence", [f"{ride.cadence_rpm[i]:g}" for i in keep])
        + array("speed", [f"{ride.speed_mps[i]:.6f}" for i in keep])
        + array("heartrate", ["140"] * POINTS) + array("temperature", ["19"] * 3)
        + "</SchemaData></ExtendedData></gx:Track></Placemark></Document></kml>")
    got = read_recording(track)
    assert got.power_w is not None and got.cadence_rpm is not None and got.speed_mps is not None
    want = ride.power_w[keep].copy()
    want[5] = np.nan
    np.testing.assert_array_equal(got.power_w, want)
    np.testing.assert_array_equal(got.cadence_rpm, ride.cadence_rpm[keep])
    np.testing.assert_allclose(got.speed_mps, ride.speed_mps[keep], atol=1e-6)
    assert got.temperature_c is None  # 3 values for 720 points: not this track's
    summary = import_ride(track, tmp_path / "ride.mcap")
    assert summary.topics["/itt/power"] == POINTS - 1 and summary.topics["/itt/speed"] == POINTS


def test_geojson_shapes_and_multilines(tmp_path: Path) -> None:
    line = [[11.0, 45.0], [11.001, 45.0], [11.002, 45.001]]
    cases = {
        "bare.geojson": {"type": "LineString", "coordinates": line},
        "multi.geojson": {"type": "Feature", "properties": {"coordTimes": [
            ["2026-05-01T10:00:00Z", "2026-05-01T10:00:01Z"], ["2026-05-01T10:00:02"]]},
            "geometry": {"type": "MultiLineString", "coordinates": [line[:2], line[2:]]}},
        "collection.geojson": {"type": "GeometryCollection", "geometries": [
            {"type": "Point", "coordinates": line[0]},
            {"type": "LineString", "coordinates": line}]},
    }
    for name, doc in cases.items():
        (tmp_path / name).write_text(json.dumps(doc))
        rec = read_recording(tmp_path / name)
        np.testing.assert_allclose(rec.lon_deg, [p[0] for p in line], err_msg=name)
        assert np.all(np.isnan(rec.ele_m)), name
    multi = read_recording(tmp_path / "multi.geojson")
    # togeojson's older per-line stamps; a stamp without a zone is UTC.
    assert multi.time_s is not None
    np.testing.assert_allclose(multi.time_s - multi.time_s[0], [0.0, 1.0, 2.0])


@pytest.mark.parametrize(("name", "content", "problem"), [
    ("markers.kml", ('<kml xmlns="http://www.opengis.net/kml/2.2"><Document><Placemark><Point>'
                     "<coordinates>11,45</coordinates></Point></Placemark></Document></kml>"),
     "no route in the KML"),
    ("bad.kml", ('<kml xmlns="http://www.opengis.net/kml/2.2"><Document><Placemark><LineString>'
                 "<coordinates>11,abc 11.1,45</coordinates></LineString></Placemark></Document>"
                 "</kml>"), "not a valid KML file"),
    ("bad.kmz", "not a zip", "not a valid KMZ"),
    ("bad.geojson", "{not json", "not valid JSON"),
    ("points.geojson", '{"type": "Point", "coordinates": [11, 45]}', "no route in the GeoJSON"),
    ("words.geojson", '{"type": "LineString", "coordinates": [["a", "b"]]}',
     "is not \\[longitude, latitude"),
    ("stamps.geojson", ('{"type": "Feature", "properties": {"coordTimes": ["noon"]}, '
                        '"geometry": {"type": "LineString", "coordinates": [[11, 45]]}}'),
     "not an ISO 8601 stamp"),
])
def test_map_file_errors_name_the_file(tmp_path: Path, name: str, content: str,
                                       problem: str) -> None:
    path = tmp_path / name
    path.write_text(content)
    with pytest.raises(CourseError, match=problem) as info:
        read_recording(path)
    assert name in str(info.value)


def test_kmz_without_a_kml_document(tmp_path: Path) -> None:
    path = tmp_path / "images.kmz"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("files/icon.png", b"\x89PNG")
    with pytest.raises(CourseError, match=r"no \.kml document inside the KMZ"):
        read_recording(path)
