"""The sweep spec: the courses, riders and conditions a sweep covers (YAML -> frozen dataclasses).

A spec file is a mapping (edge units, as on the command line: km/h, degrees)::

    name: race-eve                       # optional, default the file's stem
    courses: [verona-like, tt.gpx]       # demo names or course files (relative to this file)
    riders: [typical, specialist, anna.yaml]   # presets or rider YAML files
    axes:                                # every axis is optional (default in brackets)
      model: [1d, 3d]                    # [3d]
      wind_kmh: [0, 20, 40]              # [0]
      wind_from_deg: [0, 90, 180, 270]   # [0], direction the wind blows FROM, 0 = North
      mu: [1.0, 0.6]                     # [1.0], tyre-road grip: 1.0 dry, ~0.6 wet
      wprime_model: [skiba, paper]       # [skiba]
      equipment:                         # [stock: {}]; rider fields set (absolute) or
        stock: {}                        # changed (delta_<field>) by each choice
        aero-helmet: {drag_area_m2: 0.21}
        light-wheels: {delta_mass_kg: -0.6}
    cases:                               # optional: a listed subset instead of the product;
      - {rider: typical, mu: 0.6}        # each entry fixes some axes (one value or a list)
    solver: {max_iter: 400, max_cpu_time_s: 120}   # any `OcpSettings` field but wprime_model
    split_every_m: 1000

Without `cases` the sweep is the cartesian product of courses x riders x every axis; with
it, the union of each entry's product (an entry's unnamed axes take all their values).
Validation errors (`SweepSpecError`) name the file and the field.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from itt_planner.errors import IttError
from itt_planner.model.rider import PRESETS, Rider
from itt_planner.model.wprime import WPrimeModel
from itt_planner.ocp.course_settings import OcpSettings
from itt_planner.units import MPS_TO_KMH

MODELS = ("1d", "3d")
_TOP_KEYS = {"name", "courses", "riders", "axes", "cases", "solver", "split_every_m"}
_AXIS_KEYS = ("model", "wind_kmh", "wind_from_deg", "mu", "wprime_model", "equipment")
_CASE_KEYS = {"course", "rider", *_AXIS_KEYS}
#: Rider fields an equipment choice may set or change (numbers; `name` stays the rider's).
_RIDER_NUMBERS = tuple(f.name for f in dataclasses.fields(Rider) if f.name != "name")
_DELTA = "delta_"


class SweepSpecError(IttError):
    """A sweep spec file is unreadable or invalid (names the file and the field)."""


@dataclass(frozen=True)
class Equipment:
    """One equipment choice: rider fields set (`set_fields`) or changed (`delta_fields`)."""

    name: str
    set_fields: tuple[tuple[str, float], ...] = ()
    delta_fields: tuple[tuple[str, float], ...] = ()

    def apply(self, rider: Rider) -> Rider:
        """The rider on this equipment (raises `RiderError` if a field ends up invalid)."""
        values: dict[str, Any] = dict(self.set_fields)
        for field, delta in self.delta_fields:
            values[field] = values.get(field, getattr(rider, field)) + delta
        return dataclasses.replace(rider, **values) if values else rider


STOCK = Equipment("stock")


@dataclass(frozen=True)
class Grid:
    """One cartesian product of cases. SI units; wind as in `Conditions`."""

    courses: tuple[str, ...]
    riders: tuple[str, ...]
    models: tuple[str, ...] = ("3d",)
    wind_speeds_mps: tuple[float, ...] = (0.0,)
    wind_from_rad: tuple[float, ...] = (0.0,)
    mu: tuple[float, ...] = (1.0,)
    wprime_models: tuple[WPrimeModel, ...] = (WPrimeModel.SKIBA,)
    equipment: tuple[str, ...] = ("stock",)

    @property
    def size(self) -> int:
        return math.prod(len(getattr(self, f.name)) for f in dataclasses.fields(self))


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep: the grids to run, the equipment table and the solver settings.

    Attributes:
        courses, riders: as given in the file, paths made absolute (the case labels).
        grids: the full product, or one grid per listed `cases` entry.
        equipment: every choice the grids may name.
        settings: OCP settings of every case (its `wprime_model` is set per case).
        split_every_m: distance between the split times recorded per case.
    """

    name: str
    courses: tuple[str, ...]
    riders: tuple[str, ...]
    grids: tuple[Grid, ...]
    equipment: tuple[Equipment, ...] = (STOCK,)
    settings: OcpSettings = OcpSettings()
    split_every_m: float = 1000.0

    def equipment_named(self, name: str) -> Equipment:
        return next(e for e in self.equipment if e.name == name)


def load_spec(path: str | Path) -> SweepSpec:
    """Read and validate a sweep spec file (module docstring).

    Raises:
        SweepSpecError: unreadable file, unknown key, or an invalid value (names the field).
    """
    path = Path(path)
    try:
        raw = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as err:
        raise SweepSpecError(f"{path}: cannot read the sweep spec ({err})") from None
    try:
        return parse_spec(raw, base_dir=path.parent, default_name=path.stem.split(".")[0])
    except SweepSpecError as err:
        raise SweepSpecError(f"{path}: {err}") from None


def parse_spec(raw: Any, *, base_dir: Path = Path(), default_name: str = "sweep") -> SweepSpec:
    """Validate an already parsed spec mapping; relative course/rider files from `base_dir`."""
    if not isinstance(raw, dict):
        raise SweepSpecError(f"expected a mapping, got {type(raw).__name__}")
    _no_unknown(raw, _TOP_KEYS, "spec")
    courses = tuple(_source(v, base_dir, "courses", keep=()) for v in _strings(raw, "courses"))
    riders = tuple(_source(v, base_dir, "riders", keep=tuple(PRESETS))
                   for v in _strings(raw, "riders"))
    axes = raw.get("axes") or {}
    if not isinstance(axes, dict):
        raise SweepSpecError(f"axes: expected a mapping, got {axes!r}")
    _no_unknown(axes, set(_AXIS_KEYS), "axes")
    equipment = _equipment(axes.get("equipment", {"stock": {}}))
    full = _grid({k: v for k, v in axes.items() if k != "equipment"}, "axes",
                 Grid(courses, riders, equipment=tuple(e.name for e in equipment)))
    entries = raw.get("cases")
    if entries is None:
        grids: tuple[Grid, ...] = (full,)
    else:
        if not isinstance(entries, list) or not entries:
            raise SweepSpecError("cases: expected a non-empty list of mappings")
        grids = tuple(_case_grid(entry, i, full, base_dir) for i, entry in enumerate(entries))
    names = {e.name for e in equipment}
    for i, grid in enumerate(grids):
        missing = sorted(set(grid.equipment) - names)
        if missing:
            raise SweepSpecError(f"cases[{i}].equipment: unknown choice(s) {', '.join(missing)}")
    return SweepSpec(
        name=str(raw.get("name", default_name)), courses=courses, riders=riders, grids=grids,
        equipment=equipment, settings=_settings(raw.get("solver") or {}),
        split_every_m=_positive(raw.get("split_every_m", 1000.0), "split_every_m"))


def _no_unknown(raw: Mapping[str, Any], known: set[str], where: str) -> None:
    unknown = sorted(set(raw) - known)
    if unknown:
        raise SweepSpecError(f"{where}: unknown key(s) {', '.join(map(str, unknown))}; "
                             f"expected {', '.join(sorted(known))}")


def _strings(raw: Mapping[str, Any], key: str) -> list[str]:
    values = raw.get(key)
    if isinstance(values, str):
        values = [values]
    if not isinstance(values, list) or not values or not all(isinstance(v, str) for v in values):
        raise SweepSpecError(f"{key}: expected a non-empty list of names, got {values!r}")
    return values


def _source(value: str, base_dir: Path, field: str, keep: tuple[str, ...]) -> str:
    """A preset/demo name as is; a file relative to the spec made absolute."""
    from itt_planner.course.loader import DEMO_COURSES  # noqa: PLC0415

    if value in keep or value in DEMO_COURSES:
        return value
    path = Path(value) if Path(value).is_absolute() else base_dir / value
    if not path.is_file():
        raise SweepSpecError(f"{field}: {value!r} is neither a known name nor a file "
                             f"(looked for {path})")
    return str(path.resolve())


def _numbers(value: Any, field: str) -> tuple[float, ...]:
    values = value if isinstance(value, list) else [value]
    out = []
    for v in values:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise SweepSpecError(f"{field}: expected numbers, got {v!r}")
        out.append(float(v))
    if not out:
        raise SweepSpecError(f"{field}: expected at least one value")
    return tuple(out)


def _positive(value: Any, field: str) -> float:
    (number,) = _numbers(value, field)
    if number <= 0:
        raise SweepSpecError(f"{field}: must be positive, got {value!r}")
    return number


def _grid(axes: Mapping[str, Any], where: str, base: Grid) -> Grid:
    """`base` with the axes named in `axes` replaced (validated, converted to SI)."""
    changes: dict[str, tuple[Any, ...]] = {}
    if "model" in axes:
        models = tuple(axes["model"] if isinstance(axes["model"], list) else [axes["model"]])
        bad = [m for m in models if m not in MODELS]
        if bad or not models:
            raise SweepSpecError(f"{where}.model: expected {' or '.join(MODELS)}, got {bad}")
        changes["models"] = models
    if "wind_kmh" in axes:
        kmh = _numbers(axes["wind_kmh"], f"{where}.wind_kmh")
        if min(kmh) < 0:
            raise SweepSpecError(f"{where}.wind_kmh: wind speeds must be >= 0, got {kmh}")
        changes["wind_speeds_mps"] = tuple(v / MPS_TO_KMH for v in kmh)
    if "wind_from_deg" in axes:
        changes["wind_from_rad"] = tuple(math.radians(v % 360.0) for v in
                                         _numbers(axes["wind_from_deg"], f"{where}.wind_from_deg"))
    if "mu" in axes:
        mu = _numbers(axes["mu"], f"{where}.mu")
        if min(mu) <= 0 or max(mu) > 2:
            raise SweepSpecError(f"{where}.mu: grip must be in (0, 2], got {mu}")
        changes["mu"] = mu
    if "wprime_model" in axes:
        raw = axes["wprime_model"]
        raw = raw if isinstance(raw, list) else [raw]
        try:
            changes["wprime_models"] = tuple(WPrimeModel(str(v)) for v in raw)
        except ValueError:
            choices = ", ".join(m.value for m in WPrimeModel)
            raise SweepSpecError(f"{where}.wprime_model: expected {choices}, got {raw}") from None
    if "equipment" in axes:
        names = axes["equipment"] if isinstance(axes["equipment"], list) else [axes["equipment"]]
        changes["equipment"] = tuple(str(n) for n in names)
    grid = dataclasses.replace(base, **changes)
    for f in dataclasses.fields(grid):
        values = getattr(grid, f.name)
        if len(set(values)) != len(values):
            raise SweepSpecError(f"{where}: {f.name} lists a value twice: {values}")
    return grid


def _case_grid(entry: Any, i: int, full: Grid, base_dir: Path) -> Grid:
    where = f"cases[{i}]"
    if not isinstance(entry, dict) or not entry:
        raise SweepSpecError(f"{where}: expected a mapping of axis values, got {entry!r}")
    _no_unknown(entry, _CASE_KEYS, where)
    base = full
    for key, field, keep in (("course", "courses", ()), ("rider", "riders", tuple(PRESETS))):
        if key in entry:
            names = entry[key] if isinstance(entry[key], list) else [entry[key]]
            chosen = tuple(_source(str(n), base_dir, f"{where}.{key}", keep) for n in names)
            listed = set(getattr(full, field))
            if not set(chosen) <= listed:
                raise SweepSpecError(f"{where}.{key}: {names} not among the spec's {field}")
            change: dict[str, Any] = {field: chosen}
            base = dataclasses.replace(base, **change)
    return _grid({k: v for k, v in entry.items() if k not in ("course", "rider")}, where, base)


def _equipment(raw: Any) -> tuple[Equipment, ...]:
    if not isinstance(raw, dict) or not raw:
        raise SweepSpecError(f"axes.equipment: expected a mapping name -> rider fields, "
                             f"got {raw!r}")
    out = []
    for name, given in raw.items():
        where = f"axes.equipment.{name}"
        fields = given or {}
        if not isinstance(fields, dict):
            raise SweepSpecError(f"{where}: expected a mapping of rider fields, got {fields!r}")
        set_fields: list[tuple[str, float]] = []
        delta_fields: list[tuple[str, float]] = []
        for key, value in fields.items():
            field = key.removeprefix(_DELTA)
            if field not in _RIDER_NUMBERS:
                raise SweepSpecError(f"{where}: unknown rider field {key!r}; expected one of "
                                     f"{', '.join(_RIDER_NUMBERS)} (or delta_<field>)")
            (number,) = _numbers(value, f"{where}.{key}")
            (delta_fields if key.startswith(_DELTA) else set_fields).append((field, number))
        out.append(Equipment(str(name), tuple(set_fields), tuple(delta_fields)))
    return tuple(out)


def _settings(raw: Any) -> OcpSettings:
    if not isinstance(raw, dict):
        raise SweepSpecError(f"solver: expected a mapping of OcpSettings fields, got {raw!r}")
    known = {f.name for f in dataclasses.fields(OcpSettings)} - {"wprime_model"}
    _no_unknown(raw, known, "solver")
    defaults = OcpSettings()
    for key, value in raw.items():
        default = getattr(defaults, key)
        if isinstance(default, bool) or isinstance(value, bool):
            ok = isinstance(value, bool) and isinstance(default, bool)
        elif isinstance(default, int):
            ok = isinstance(value, int) and value > 0
        else:  # float fields, and uniform_m (None or a spacing)
            ok = (value is None and default is None) or (
                isinstance(value, (int, float)) and math.isfinite(value) and value >= 0)
        if not ok:
            raise SweepSpecError(f"solver.{key}: invalid value {value!r} "
                                 f"(default {default!r})")
    return dataclasses.replace(defaults, **raw)
