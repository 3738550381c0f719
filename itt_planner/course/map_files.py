"""Read routes drawn on web maps (`track_files` makes them a `Recording`): KML and KMZ
(Google Earth, Google My Maps, RideWithGPS) through fastkml, and GeoJSON (geojson.io,
OpenRouteService, togeojson's conversions of GPX), which is plain JSON (RFC 7946).

Only lines make a route: a KML Placemark's LineString (also inside a MultiGeometry) or its
gx:Track / gx:MultiTrack (with their stamps); a GeoJSON LineString or MultiLineString, bare,
in a Feature, a FeatureCollection or a GeometryCollection, with togeojson's stamps per point
(`properties.coordinateProperties.times`, or the older `properties.coordTimes`). Markers
(points) and areas (polygons) are not read. Several lines are joined in document order, as
the GPX reader joins tracks and segments. Coordinates are longitude, latitude and, when
given, altitude in metres. A gx:Track's `ExtendedData` arrays (`gx:SimpleArrayData`, as
Google Earth and GPS Visualizer write a ride's sensors) give power, speed, cadence and
temperature by `SENSOR_NAMES`.

Also what every track format shares: the clean-up before an XML declaration (`xml_text`),
the sensor names (`SENSOR_NAMES`, the GPX reader's extensions too), ISO 8601 stamps
(`iso_stamp_s`, a CSV's times too) and a multisport file's ride leg (`ride_leg`, TCX's
and FIT's).
"""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from itt_planner.errors import CourseError

#: Sensor values beside the points, by their name in the file in lower case: GPX extensions
#: (Garmin's TrackPointExtension `speed`, `cad`, `atemp`, its PowerExtension
#: `PowerInWatts`, a plain `<power>`) and gx:Track arrays (`power`, `cadence`, ...).
SENSOR_NAMES = {"power": "power", "powerinwatts": "power", "watts": "power",
                "speed": "speed", "cad": "cadence", "cadence": "cadence",
                "atemp": "temperature", "temp": "temperature", "temperature": "temperature"}
#: The sensors a route point carries after its stamp, in this order.
SENSORS = ("power", "speed", "cadence", "temperature")
#: One route point: longitude, latitude, altitude (NaN when absent), POSIX stamp (NaN),
#: then `SENSORS` (NaN when absent).
_Row = tuple[float, ...]
_NAN = float("nan")
_NO_SENSORS = (_NAN,) * len(SENSORS)
T = TypeVar("T")


@dataclass(frozen=True, eq=False)
class MapRoute:
    """A route's points in file order; NaN where a file has no altitude or stamp.

    Attributes:
        time_s: POSIX seconds, or None when no point has a stamp.
        sensors: each of `SENSORS` that some point has (NaN at the others), in SI units
            but cadence (rpm) and temperature (C).
        sport: the sport the file names ("" when none).
    """

    lat_deg: np.ndarray
    lon_deg: np.ndarray
    ele_m: np.ndarray
    time_s: np.ndarray | None
    sensors: dict[str, np.ndarray]
    sport: str = ""


def ride_leg(path: Path, legs: list[tuple[str, list[T]]], *, is_ride: Callable[[str], bool],
             fixes: Callable[[list[T]], int], points: str, missing: str) -> list[T]:
    """The points of a multisport file's ride leg with the most GPS positions; `legs`:
    (sport, its points) in file order.

    Raises:
        CourseError: no ride leg has 3 positions or more: "{path}: a multisport {missing}
            with GPS positions (...)", naming every leg with its `points` and positions.
    """
    rides = [leg for sport, leg in legs if is_ride(sport) and fixes(leg) >= 3]
    if not rides:
        found = "; ".join(f"{sport}: {len(leg)} {points}, {fixes(leg)} with a position"
                          for sport, leg in legs)
        raise CourseError(f"{path}: a multisport {missing} with GPS positions ({found})")
    return max(rides, key=fixes)


def sensor_value(text: str | None) -> float:
    """A sensor reading as written in a file; NaN when missing or not a number (one bad
    value is a missing reading, not a broken file)."""
    try:
        return float(text) if text else _NAN
    except ValueError:
        return _NAN


def iso_stamp_s(text: str) -> float:
    """POSIX seconds of an ISO 8601 stamp; one without a zone is UTC, as GPX's and KML's
    are. Raises ValueError (TypeError for a non-string) when it is not a stamp."""
    stamp = datetime.fromisoformat(text)
    return (stamp if stamp.tzinfo else stamp.replace(tzinfo=UTC)).timestamp()


def xml_text(data: bytes) -> bytes:
    """XML with what comes before its declaration removed (a byte-order mark, Strava's
    spaces): XML allows nothing there, and such exports are otherwise well formed."""
    return data.removeprefix(b"\xef\xbb\xbf").lstrip()


def read_kml(path: Path, data: bytes, *, kmz: bool) -> MapRoute:
    """The lines of a KML file, or of the KML inside a KMZ (`doc.kml`, else its first)."""
    from fastkml import KML  # noqa: PLC0415  (lazy: only KML needs it)

    if kmz:
        data = _kmz_document(path, data)
    # Not validated against the schema: exports carry vendors' extensions; bad coordinates
    # still raise (strict parsing).
    kml = KML.parse(io.BytesIO(xml_text(data)), validate=False)
    rows = [row for placemark in _placemarks(kml) for row in _kml_rows(placemark)]
    if not rows:
        raise CourseError(f"{path}: no route in the KML (a LineString or gx:Track in a "
                          "Placemark; points and polygons are not a route)")
    return route_from_rows(rows)


def read_geojson(path: Path, data: bytes) -> MapRoute:
    """The lines of a GeoJSON document (module docstring)."""
    try:
        doc = json.loads(data)
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise CourseError(f"{path}: not valid JSON ({err})") from None
    rows = list(_geojson_rows(path, doc, {}))
    if not rows:
        raise CourseError(f"{path}: no route in the GeoJSON (a LineString or MultiLineString; "
                          "points and polygons are not a route)")
    return route_from_rows(rows)


def route_from_rows(rows: list[tuple[float, ...]], sport: str = "") -> MapRoute:
    """Rows of (longitude, latitude, altitude, POSIX stamp, `SENSORS`...; NaN where
    absent) as a route."""
    arr = np.array(rows, dtype=float)
    stamps = arr[:, 3]
    sensors = {name: arr[:, 4 + k] for k, name in enumerate(SENSORS)
               if np.isfinite(arr[:, 4 + k]).any()}
    return MapRoute(lat_deg=arr[:, 1], lon_deg=arr[:, 0], ele_m=arr[:, 2],
                    time_s=None if np.all(np.isnan(stamps)) else stamps, sensors=sensors,
                    sport=sport)


def _kmz_document(path: Path, data: bytes) -> bytes:
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as kmz:
            names = [n for n in kmz.namelist() if n.lower().endswith(".kml")]
            if not names:
                raise CourseError(f"{path}: no .kml document inside the KMZ")
            return kmz.read("doc.kml" if "doc.kml" in names else names[0])
    except zipfile.BadZipFile as err:
        raise CourseError(f"{path}: not a valid KMZ (zip) file ({err})") from None


def _placemarks(feature: Any) -> Iterator[Any]:
    """Every Placemark under a KML object, in document order (through Documents, Folders)."""
    from fastkml import Placemark  # noqa: PLC0415

    if isinstance(feature, Placemark):
        yield feature
    for child in getattr(feature, "features", None) or ():
        yield from _placemarks(child)


def _kml_rows(placemark: Any) -> Iterator[_Row]:
    """A Placemark's route points. Read from fastkml's own objects, not their pygeoif
    shapes, which drop repeated points (a stamped track's standing still)."""
    from fastkml import geometry, gx  # noqa: PLC0415

    shapes = [placemark.kml_geometry]
    while shapes:
        shape = shapes.pop(0)
        if isinstance(shape, gx.MultiTrack | geometry.MultiGeometry):
            shapes[:0] = list(shape.tracks if isinstance(shape, gx.MultiTrack)
                              else shape.kml_geometries)
        elif isinstance(shape, gx.Track):
            items = list(shape.track_items or ())
            sensors = _track_sensors(shape, len(items))
            for k, item in enumerate(items):
                # A <when> may be a bare date: no stamp for the point then.
                when = item.when.dt if item.when else None
                stamp = when.timestamp() if isinstance(when, datetime) else _NAN
                yield (*_position(next(iter(item.coord.coords))), stamp,
                       *(values[k] for values in sensors))
        elif isinstance(shape, geometry.LineString) and shape.kml_coordinates:
            yield from ((*_position(xyz), _NAN, *_NO_SENSORS)
                        for xyz in shape.kml_coordinates.coords)


def _track_sensors(track: Any, n: int) -> list[list[float]]:
    """A gx:Track's `SENSORS` arrays from its ExtendedData, each `n` long (NaN where an
    array is missing, or is not one value per point)."""
    arrays = {name: [_NAN] * n for name in SENSORS}
    extended = getattr(track, "extended_data", None)
    for schema_data in getattr(extended, "elements", None) or ():
        for array in getattr(schema_data, "array_data", None) or ():
            name = SENSOR_NAMES.get(str(array.name or "").lower())
            if name and len(array.data or ()) == n:
                arrays[name] = [sensor_value(v) for v in array.data]
    return [arrays[name] for name in SENSORS]


def _position(xyz: tuple[float, ...]) -> tuple[float, float, float]:
    return float(xyz[0]), float(xyz[1]), float(xyz[2]) if len(xyz) > 2 else _NAN


def _geojson_rows(path: Path, obj: Any, props: dict[str, Any]) -> Iterator[_Row]:
    """The route points of a GeoJSON object; `props` are its Feature's properties."""
    if not isinstance(obj, dict):
        raise CourseError(f"{path}: a GeoJSON object is not a JSON object: {str(obj)[:60]!r}")
    kind = obj.get("type")
    if kind == "FeatureCollection":
        for feature in obj.get("features") or ():
            yield from _geojson_rows(path, feature, {})
    elif kind == "Feature":
        if obj.get("geometry") is not None:
            yield from _geojson_rows(path, obj["geometry"], obj.get("properties") or {})
    elif kind == "GeometryCollection":
        for part in obj.get("geometries") or ():
            yield from _geojson_rows(path, part, {})
    elif kind in ("LineString", "MultiLineString"):
        lines = obj.get("coordinates")
        lines = [lines] if kind == "LineString" else lines
        times = (props.get("coordinateProperties") or {}).get("times", props.get("coordTimes"))
        times = [times] if kind == "LineString" else times
        for k, line in enumerate(lines or ()):
            stamps = _stamps(path, times[k] if isinstance(times, list) and k < len(times)
                             else None, len(line))
            for xyz, stamp in zip(line, stamps, strict=True):
                if not (isinstance(xyz, list) and len(xyz) >= 2
                        and all(isinstance(c, int | float) for c in xyz)):
                    raise CourseError(f"{path}: a {kind} position is not [longitude, "
                                      f"latitude(, altitude)] numbers: {xyz!r}")
                yield *_position(tuple(xyz)), stamp, *_NO_SENSORS
    elif not isinstance(kind, str):
        raise CourseError(f"{path}: a GeoJSON object without a 'type': {str(obj)[:60]!r}")


def _stamps(path: Path, times: Any, n: int) -> list[float]:
    """togeojson's ISO 8601 stamps of one line, or NaN for each point without them."""
    if not isinstance(times, list) or len(times) != n:
        return [_NAN] * n
    try:
        # A stamp without a zone is UTC, as GPX's and KML's are.
        return [iso_stamp_s(t) if t else _NAN for t in times]
    except (TypeError, ValueError) as err:
        raise CourseError(f"{path}: a point's time is not an ISO 8601 stamp ({err})") from None
