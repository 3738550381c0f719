"""Read back a rider file `calibrate` wrote: each fitted value with its uncertainty and source.

`calibrate.rider_yaml` writes the values as YAML fields (what `--rider` loads) and what
the loader ignores as comments: the rides it was fitted on (first line, `YAML_HEADER`),
the day's wind per ride, the CdA per setup, each refusal, and beside each field its
uncertainty and where it came from. The report shows them; a rider file written by hand
(no header) is not a calibrated rider and reads as None.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from itt_planner.calibration.calibrate import YAML_HEADER
from itt_planner.calibration.ride_data import CalibrationError

#: A field line with its note: `name: value  # note`.
_FIELD_NOTE = re.compile(r"^(\w+):\s*(.*?)\s+#\s?(.*)$")
_REFUSED = "# refused "
_WARNING = "# warning "


@dataclass(frozen=True)
class CalibratedRiderFile:
    """What a calibrated rider file says.

    Attributes:
        values: every YAML field (preset, name and the fitted or given values).
        notes: field -> its uncertainty and source, as written beside it.
        conditions: the comment lines about the rides, not the rider (the day's wind per
            ride, the CdA per setup), without the leading `# `.
        refusals: estimator -> why it refused (its field kept the preset's value).
        warnings: estimator -> why its fitted values may not be the rider's.
    """

    path: Path
    sources: tuple[str, ...]
    values: dict[str, Any]
    notes: dict[str, str]
    conditions: tuple[str, ...]
    refusals: dict[str, str]
    warnings: dict[str, str]


def read_calibrated_rider(path: str | Path) -> CalibratedRiderFile | None:
    """The calibration record of a rider file; None for a preset name or a file that
    `calibrate` did not write (no `YAML_HEADER` first line).

    Raises:
        CalibrationError: the file starts as a calibrated rider but is not readable YAML.
    """
    path = Path(path)
    if not path.is_file():
        return None  # a preset name
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return None  # not a rider file at all: the rider loader says why
    lines = text.splitlines()
    if not lines or not lines[0].startswith(YAML_HEADER):
        return None
    try:
        values = yaml.safe_load(text) or {}
    except yaml.YAMLError as err:
        raise CalibrationError(f"{path}: calibrated rider file is not valid YAML ({err})"
                               ) from None
    if not isinstance(values, dict):
        raise CalibrationError(f"{path}: calibrated rider file is not a mapping of fields")
    notes: dict[str, str] = {}
    conditions: list[str] = []
    refusals: dict[str, str] = {}
    warnings: dict[str, str] = {}
    for line in lines[1:]:
        if line.startswith(_REFUSED):
            name, _, reason = line[len(_REFUSED):].partition(": ")
            refusals[name] = reason
        elif line.startswith(_WARNING):
            name, _, reason = line[len(_WARNING):].partition(": ")
            warnings[name] = reason
        elif line.startswith("#"):
            conditions.append(line.lstrip("# "))
        elif match := _FIELD_NOTE.match(line):
            notes[match.group(1)] = match.group(3)
    sources = tuple(lines[0][len(YAML_HEADER):].split(", "))
    return CalibratedRiderFile(path, sources, values, notes, tuple(conditions), refusals,
                               warnings)
