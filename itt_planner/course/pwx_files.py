"""Read PWX workout files (TrainingPeaks' XML format: WKO, TrainingPeaks' device agent,
GoldenCheetah and IpBike write it) into a `map_files.MapRoute`.

A `<pwx>` holds one `<workout>` per activity: its `<sportType>` (Bike, Run, ...), its
start `<time>` (ISO 8601; without a zone read as UTC, as GPX's) and its `<sample>`s, each
stamped by `<timeoffset>` seconds from that start with what the device recorded of
`lat`/`lon` (degrees), `alt` (m), `spd` (m/s), `pwr` (W), `cad` (rpm) and `temp` (C).
Several workouts are joined in file order, as a GPX file's tracks are; the sport is the
first workout's that names one.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from itt_planner.course.map_files import (
    SENSORS,
    MapRoute,
    iso_stamp_s,
    route_from_rows,
    sensor_value,
    xml_text,
)
from itt_planner.errors import CourseError

#: The PWX tag of each of `map_files.SENSORS`.
_SENSOR_TAGS = {"power": "pwr", "speed": "spd", "cadence": "cad", "temperature": "temp"}


def read_pwx(path: Path, data: bytes) -> MapRoute:
    """The samples of every workout in a PWX file (module docstring).

    Raises:
        CourseError: no `<pwx>` root, or no sample in any workout.
        ET.ParseError, ValueError: malformed XML or a start time that is not a stamp (the
            caller names the file).
    """
    root = ET.fromstring(xml_text(data))
    ns = root.tag[: root.tag.index("}") + 1] if root.tag.startswith("{") else ""
    if root.tag != f"{ns}pwx":
        raise CourseError(f"{path}: not a PWX file (its root is <{root.tag[len(ns):]}>)")
    rows: list[tuple[float, ...]] = []
    sport = ""
    for workout in root.iter(f"{ns}workout"):
        sport = sport or (workout.findtext(f"{ns}sportType") or "").strip()
        start = (workout.findtext(f"{ns}time") or "").strip()
        start_s = iso_stamp_s(start) if start else float("nan")
        for sample in workout.iter(f"{ns}sample"):
            def value(tag: str, sample: ET.Element = sample) -> float:
                return sensor_value(sample.findtext(f"{ns}{tag}"))

            rows.append((value("lon"), value("lat"), value("alt"),
                         start_s + value("timeoffset"),
                         *(value(_SENSOR_TAGS[name]) for name in SENSORS)))
    if not rows:
        raise CourseError(f"{path}: no samples in the PWX file")
    return route_from_rows(rows, sport)
