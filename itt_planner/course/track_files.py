"""Read GPS track and ride files (GPX tracks and routes, TCX activities and courses, FIT,
CSV, TrainingPeaks' PWX in `pwx_files`, and the routes of web maps, KML/KMZ and GeoJSON,
in `map_files`; each also gzipped) into one record type.

Courses use only the positions; ride import also uses the stamps, speed and power.
Parsing is left to well-kept libraries (gpxpy, tcxreader, fitdecode in `fit_records`);
this module only maps their records onto `Recording` arrays and turns their failures into
`CourseError` naming the file.

Two quirks of real exports are read as their authors meant: Strava's bulk export gzips
its files (`123.fit.gz`, `123.tcx.gz`) and writes TCX (and some GPX) with spaces before
the `<?xml` declaration, which strict XML parsers refuse.
"""

from __future__ import annotations

import csv
import gzip
import hashlib
import io
import math
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from itt_planner.course.fit_records import read_fit_activity
from itt_planner.course.map_files import (
    SENSOR_NAMES,
    MapRoute,
    iso_stamp_s,
    read_geojson,
    read_kml,
    ride_leg,
    sensor_value,
    xml_text,
)
from itt_planner.course.pwx_files import read_pwx
from itt_planner.errors import CourseError

#: FIT stores positions in semicircles: 2^31 semicircles = 180 degrees.
_SEMICIRCLE_DEG = 180.0 / 2**31
SUFFIXES = (".gpx", ".tcx", ".fit", ".csv", ".kml", ".kmz", ".geojson", ".pwx")
#: A gzipped file of one of `SUFFIXES` (`ride.fit.gz`) is read as that format.
GZIP_SUFFIX = ".gz"


@dataclass(frozen=True, eq=False)
class Recording:
    """Samples of a GPS track or ride. Missing values are NaN; times may be absent.

    Attributes:
        time_s: POSIX seconds of each sample, or None for tracks without stamps.
    """

    path: Path
    sha256: str
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    ele_m: np.ndarray
    time_s: np.ndarray | None = None
    speed_mps: np.ndarray | None = None
    power_w: np.ndarray | None = None
    cadence_rpm: np.ndarray | None = None
    #: The head unit's air temperature (C), for the air density.
    temperature_c: np.ndarray | None = None
    device: str = ""
    #: The activity's sport as the file names it (FIT session, TCX `Sport`, GPX track
    #: `type`); "" when it names none.
    sport: str = ""

    def __len__(self) -> int:
        return len(self.lat_deg)

    def air_temperature_c(self, index: np.ndarray | None = None) -> float:
        """The median of the air temperatures recorded (at `index`, else everywhere), NaN
        when there are none: the day's air, whatever the sun did to the head unit for a
        while."""
        if self.temperature_c is None:
            return math.nan
        values = self.temperature_c if index is None else self.temperature_c[index]
        values = values[np.isfinite(values)]
        return float(np.median(values)) if len(values) else math.nan

    @property
    def other_sport(self) -> bool:
        """The file names a sport that is not cycling (a run, a swim, a walk...)."""
        return any(word in self.sport.lower() for word in _OTHER_SPORTS)


#: Words of the sports that are not a ride, as FIT, TCX and GPX files name them (a
#: number, Strava's GPX code, is none of them: unknown, read as a ride).
_OTHER_SPORTS = ("run", "walk", "hik", "swim", "row", "ski", "paddl", "kayak", "canoe",
                 "skat")


def file_sha256(path: Path) -> str:
    """SHA-256 of a file's bytes, used to key courses and plans to their source."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def track_format(path: str | Path) -> str:
    """The track format a file's name says, one of `SUFFIXES` (`.fit` for `ride.fit` and
    `ride.fit.gz`), or "" when it names none."""
    suffixes = [s.lower() for s in Path(path).suffixes[-2:]]
    if suffixes and suffixes[-1] == GZIP_SUFFIX:
        suffixes.pop()
    return suffixes[-1] if suffixes and suffixes[-1] in SUFFIXES else ""


def track_bytes(path: Path) -> bytes:
    """A track file's content, decompressed when its name ends in `.gz`.

    Raises:
        CourseError: missing, empty or not gzip data (names the file).
    """
    if not path.is_file():
        raise CourseError(f"{path}: no such file")
    data = path.read_bytes()
    if path.suffix.lower() == GZIP_SUFFIX:
        try:
            data = gzip.decompress(data)
        except (OSError, EOFError, zlib.error) as err:
            raise CourseError(f"{path}: not a valid gzip file ({err})") from None
    if not data:
        raise CourseError(f"{path}: the file is empty")
    return data


def read_recording(path: str | Path) -> Recording:
    """Read a GPX, TCX, FIT, CSV, PWX, KML, KMZ or GeoJSON file, or one of those gzipped
    (`ride.fit.gz`).

    Raises:
        CourseError: missing or empty file, unknown suffix, or a parser failure, with the
            file name in the message.
    """
    path = Path(path)
    suffix = track_format(path)
    readers = {".gpx": _read_gpx, ".tcx": _read_tcx, ".fit": _read_fit, ".csv": _read_csv,
               ".kml": _read_kml, ".kmz": _read_kml, ".geojson": _read_geojson,
               ".pwx": _read_pwx}
    if not suffix:
        msg = (f"{path}: unknown track format {path.suffix.lower()!r}; expected one of "
               f"{', '.join(SUFFIXES)} (or the same gzipped, {GZIP_SUFFIX})")
        raise CourseError(msg)
    data = track_bytes(path)
    try:
        rec = readers[suffix](path, data)
    except CourseError:
        raise
    except Exception as err:  # noqa: BLE001  (the parsers raise many unrelated types on bad input)
        msg = f"{path}: not a valid {suffix[1:].upper()} file ({type(err).__name__}: {err})"
        raise CourseError(msg) from None
    if len(rec) == 0:
        raise CourseError(f"{path}: no track points found")
    return rec


def _arr(values: list[float | None]) -> np.ndarray:
    return np.array([np.nan if v is None else float(v) for v in values], dtype=float)


def _opt(values: list[float | None]) -> np.ndarray | None:
    arr = _arr(values)
    return None if np.all(np.isnan(arr)) else arr


def _map_recording(path: Path, route: MapRoute) -> Recording:
    sensors = route.sensors
    return Recording(path=path, sha256=file_sha256(path), lat_deg=route.lat_deg,
                     lon_deg=route.lon_deg, ele_m=route.ele_m, time_s=route.time_s,
                     power_w=sensors.get("power"), speed_mps=sensors.get("speed"),
                     cadence_rpm=sensors.get("cadence"),
                     temperature_c=sensors.get("temperature"), sport=route.sport)


def _read_kml(path: Path, data: bytes) -> Recording:
    return _map_recording(path, read_kml(path, data, kmz=track_format(path) == ".kmz"))


def _read_geojson(path: Path, data: bytes) -> Recording:
    return _map_recording(path, read_geojson(path, data))


def _read_pwx(path: Path, data: bytes) -> Recording:
    return _map_recording(path, read_pwx(path, data))


def _gpx_extensions(point: Any) -> dict[str, float]:
    """The `SENSOR_NAMES` values of a GPX point's extensions (NaN: not a number)."""
    out: dict[str, float] = {}
    for ext in point.extensions:
        for el in ext.iter():
            name = SENSOR_NAMES.get(str(el.tag).rpartition("}")[2].lower())
            if name and el.text:
                out[name] = sensor_value(el.text)
    return out


def _read_gpx(path: Path, data: bytes) -> Recording:
    import gpxpy  # noqa: PLC0415  (lazy: only GPX needs it)

    gpx = gpxpy.parse(xml_text(data).decode("utf-8", errors="replace"))
    # Track points, or a route's points (gpxpy types them apart; both have what is read).
    points: list[Any] = [p for trk in gpx.tracks for seg in trk.segments for p in seg.points]
    if not points:
        points = [p for rte in gpx.routes for p in rte.points]
    times = [p.time.timestamp() if p.time else None for p in points]
    ext = [_gpx_extensions(p) for p in points]
    return Recording(
        path=path, sha256=file_sha256(path),
        lat_deg=_arr([p.latitude for p in points]), lon_deg=_arr([p.longitude for p in points]),
        ele_m=_arr([p.elevation for p in points]), time_s=_opt(times),
        speed_mps=_opt([e.get("speed") for e in ext]), power_w=_opt([e.get("power") for e in ext]),
        cadence_rpm=_opt([e.get("cadence") for e in ext]),
        temperature_c=_opt([e.get("temperature") for e in ext]),
        device=gpx.creator or "",
        sport=next((str(trk.type) for trk in gpx.tracks if trk.type), ""),
    )


def _read_tcx(path: Path, data: bytes) -> Recording:
    """An activity, a course (Garmin Connect's route export: `<Courses>`) or the bike leg
    of a multisport session (a triathlon: `<MultiSportSession>`), the last two skipped by
    tcxreader's `read`; its own trackpoint parser reads their points.

    Raises:
        CourseError: a multisport session without a Biking activity with positions.
    """
    import xml.etree.ElementTree as ET  # noqa: PLC0415

    from tcxreader.tcx_track_point import TCXTrackPoint  # noqa: PLC0415
    from tcxreader.tcxreader import GARMIN_XML_SCHEMA as NS  # noqa: PLC0415
    from tcxreader.tcxreader import TCXReader  # noqa: PLC0415

    reader = TCXReader()

    def points(track_points: Any) -> list[Any]:
        out = []
        for el in track_points:
            tp = TCXTrackPoint(tpx_ext={})
            reader.trackpoint_parser(tp, el)
            out.append(tp)
        return out

    xml = xml_text(data)
    # `read` takes a path, which it hands to ElementTree's `parse`: a file object works too.
    # All trackpoints: its default drops those before the first fix and after the last,
    # and their power and speed with them (a head unit that found no GPS for minutes).
    ex = reader.read(io.BytesIO(xml), only_gps=False)
    tps = ex.trackpoints or []
    sport = str(getattr(ex, "activity_type", "") or "") if tps else ""
    if not tps:
        root = ET.fromstring(xml)
        tps = points(root.iterfind(f"{NS}Courses/{NS}Course/{NS}Track/{NS}Trackpoint"))
        legs = [(act.get("Sport", "?"), points(act.iterfind(f"{NS}Lap/{NS}Track/{NS}Trackpoint")))
                for act in root.iterfind(f".//{NS}MultiSportSession//{NS}Activity")]
        if not tps and legs:
            tps, sport = _bike_leg(path, legs), "Biking"
    return Recording(
        path=path, sha256=file_sha256(path),
        lat_deg=_arr([tp.latitude for tp in tps]), lon_deg=_arr([tp.longitude for tp in tps]),
        ele_m=_arr([tp.elevation for tp in tps]),
        time_s=_opt([tp.time.timestamp() if tp.time else None for tp in tps]),
        speed_mps=_opt([tp.tpx_ext.get("Speed") if tp.tpx_ext else None for tp in tps]),
        power_w=_opt([tp.tpx_ext.get("Watts") if tp.tpx_ext else None for tp in tps]),
        cadence_rpm=_opt([tp.cadence for tp in tps]),
        device=str(getattr(ex, "device", "") or ""), sport=sport,
    )


def _bike_leg(path: Path, legs: list[tuple[str, list[Any]]]) -> list[Any]:
    """The trackpoints of a multisport session's Biking activity with the most positions
    (a duathlon has one; a file of several days' sessions may have more).

    Raises:
        CourseError: no Biking activity has 3 positions or more (naming every activity).
    """
    def fixes(tps: list[Any]) -> int:
        return sum(tp.latitude is not None and tp.longitude is not None for tp in tps)

    return ride_leg(path, legs, is_ride="Biking".__eq__, fixes=fixes, points="trackpoints",
                    missing="session without a Biking activity")


def _read_fit(path: Path, data: bytes) -> Recording:
    """A FIT activity (only the bike leg of a multisport one: `fit_records`)."""
    activity = read_fit_activity(path, data)
    rows = activity.records

    def col(*names: str, scale: float = 1.0) -> list[float | None]:
        out: list[float | None] = []
        for row in rows:
            value = next((row[n] for n in names if row.get(n) is not None), None)
            out.append(None if value is None else float(value) * scale)
        return out

    times = [r["timestamp"].timestamp() if r.get("timestamp") else None for r in rows]
    return Recording(
        path=path, sha256=file_sha256(path),
        lat_deg=_arr(col("position_lat", scale=_SEMICIRCLE_DEG)),
        lon_deg=_arr(col("position_long", scale=_SEMICIRCLE_DEG)),
        ele_m=_arr(col("enhanced_altitude", "altitude")), time_s=_opt(times),
        speed_mps=_opt(col("enhanced_speed", "speed")), power_w=_opt(col("power")),
        cadence_rpm=_opt(col("cadence")), temperature_c=_opt(col("temperature")),
        device=activity.device, sport=activity.sport,
    )


#: CSV header names of each column read (lower case), and the factor to SI units.
_CSV_COLUMNS: dict[str, tuple[tuple[str, ...], float]] = {
    "lat": (("lat", "latitude"), 1.0), "lon": (("lon", "lng", "long", "longitude"), 1.0),
    "ele": (("ele", "elevation", "alt", "altitude"), 1.0), "time": (("time", "timestamp"), 1.0),
    "power": (("power", "watts"), 1.0), "speed": (("speed",), 1.0),
    "speed_kmh": (("kph", "kmh", "speed_kmh"), 1 / 3.6), "cadence": (("cadence", "cad"), 1.0),
    "temperature": (("temperature", "temp", "atemp"), 1.0),
}


def _read_csv(path: Path, data: bytes) -> Recording:
    """CSV either `lon,lat,ele` without header, or with a header naming its columns
    (`_CSV_COLUMNS`; time as POSIX seconds or ISO 8601, a zone-less stamp being UTC)."""
    text = data.decode("utf-8-sig", errors="replace")
    rows = [r for r in csv.reader(io.StringIO(text)) if r and any(c.strip() for c in r)]
    if not rows:
        raise CourseError(f"{path}: no rows")
    header = [c.strip().lower() for c in rows[0]]
    if any(h in _CSV_COLUMNS["lat"][0] for h in header):
        cols = {key: next((header.index(a) for a in names if a in header), None)
                for key, (names, _) in _CSV_COLUMNS.items()}
        if cols["lon"] is None:
            raise CourseError(f"{path}: header has a latitude but no longitude column")
        body = rows[1:]
    else:
        if len(rows[0]) < 2:
            raise CourseError(f"{path}: expected 'lon,lat[,ele]' rows, got {rows[0]!r}")
        cols = dict.fromkeys(_CSV_COLUMNS)
        cols.update(lon=0, lat=1, ele=2 if len(rows[0]) > 2 else None)
        body = rows

    def column(key: str) -> list[float | None]:
        i = cols[key]
        out: list[float | None] = []
        for line_no, row in enumerate(body, start=2 if body is not rows else 1):
            if i is None or i >= len(row) or not row[i].strip():
                out.append(None)
                continue
            try:
                out.append(_csv_number(row[i], key) * _CSV_COLUMNS[key][1])
            except ValueError:
                msg = (f"{path}: line {line_no}: {key} {row[i]!r} is not a number"
                       + (" or an ISO 8601 time" if key == "time" else ""))
                raise CourseError(msg) from None
        return out

    speed = _opt(column("speed"))
    return Recording(
        path=path, sha256=file_sha256(path), lat_deg=_arr(column("lat")),
        lon_deg=_arr(column("lon")), ele_m=_arr(column("ele")), time_s=_opt(column("time")),
        speed_mps=speed if speed is not None else _opt(column("speed_kmh")),
        power_w=_opt(column("power")), cadence_rpm=_opt(column("cadence")),
        temperature_c=_opt(column("temperature")),
    )


def _csv_number(text: str, key: str) -> float:
    """A CSV cell as a number; a time may also be an ISO 8601 stamp (UTC without a zone)."""
    try:
        return float(text)
    except ValueError:
        if key != "time":
            raise
    return iso_stamp_s(text.strip())
