"""Calibrate one rider from ride files: run the estimators, collect refusals, write the YAML.

`calibrate` reads the rides, fits CdA/crr (and the mass when not given, `aero`),
CP/W' (`power_curve`) and the cornering limit (`cornering`) independently: a refusal of
one (no corners, too short for CP) is reported with its reason and leaves that field at
the preset's value; only when every estimator refuses is the calibration an error.
`rider_yaml` writes a file `rider.load_rider` (`--rider`) reads, with each value's
uncertainty and source as a comment beside it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

from itt_planner.calibration.aero import AeroFit, AeroSettings, fit_aero
from itt_planner.calibration.cornering import CorneringFit, fit_cornering
from itt_planner.calibration.elevation_check import check_ride_altitude
from itt_planner.calibration.power_curve import CpFit, fit_cp, mmp_curve, submaximal_warning
from itt_planner.calibration.ride_data import (
    CalibrationError,
    MissingChannelError,
    PowerSeries,
    RideSeries,
    prepare_power,
    prepare_ride,
    record_setup,
)
from itt_planner.course.geometry import Course
from itt_planner.course.track_files import Recording, read_recording
from itt_planner.errors import CourseError
from itt_planner.model.rider import PRESETS, Rider

#: First line of a rider file `rider_yaml` writes (`rider_file` reads it back by it).
YAML_HEADER = "# itt-planner calibrate: "

@dataclass(frozen=True)
class CalibrationOptions:
    """What the rides do not say.

    Attributes:
        mass_kg: rider + bicycle; None: estimated from the rides' climbs.
        drivetrain_efficiency: wheel power / measured power (a rider field).
        temperature_c: air temperature; None: the FIT records', else 15 C.
        course: one course for every ride (spec for `load_course`); None: each ride's
            own GPS track is fitted as its course (for the corners).
        allow_virtual: fit a ride whose speed is simulated (a virtual ride) anyway.
        preset: the rider the unfitted fields come from.
        setups: per ride, its setup (position or bike): one CdA per distinct setup;
            empty: the bike profile each FIT file names, else one setup for all.
    """

    mass_kg: float | None = None
    drivetrain_efficiency: float = 1.0
    temperature_c: float | None = None
    crr_prior: float = 0.004
    course: str | None = None
    allow_virtual: bool = False
    preset: str = "paper"
    name: str = "calibrated"
    setups: tuple[str, ...] = ()


@dataclass(eq=False)
class CalibrationResult:
    """Every fit, every refusal (estimator -> reason), every fit kept with a warning
    (estimator -> why its values may not be the rider's) and the resulting rider."""

    sources: list[str]
    rider: Rider
    rides: list[RideSeries]
    power_rides: list[PowerSeries] = field(default_factory=list)
    mmp_w: dict[int, float] = field(default_factory=dict)
    aero: AeroFit | None = None
    cp_2p: CpFit | None = None
    cp_3p: CpFit | None = None
    cornering: CorneringFit | None = None
    refusals: dict[str, str] = field(default_factory=dict)
    warnings: dict[str, str] = field(default_factory=dict)
    options: CalibrationOptions = CalibrationOptions()
    setup_names: list[str] = field(default_factory=list)
    setup_of_ride: list[int] = field(default_factory=list)

    def setup_riders(self) -> dict[str, Rider]:
        """The rider in each setup (its CdA), when the rides have several setups."""
        if self.aero is None or len(self.setup_names) < 2:
            return {}
        return {name: dataclasses.replace(self.rider, name=f"{self.rider.name}-{name}",
                                          drag_area_m2=cda)
                for name, cda in zip(self.setup_names, self.aero.setup_cda_m2, strict=True)}

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary (the CLI's `--json` object)."""
        return {
            "rides": self.sources,
            "rider": {k: (round(v, 5) if isinstance(v, float) else v)
                      for k, v in dataclasses.asdict(self.rider).items()},
            "aero": None if self.aero is None else self.aero.as_dict(),
            "cp_2p": None if self.cp_2p is None else self.cp_2p.as_dict(),
            "cp_3p": None if self.cp_3p is None else self.cp_3p.as_dict(),
            "cornering": None if self.cornering is None else self.cornering.as_dict(),
            "mmp_w": {str(k): round(v, 1) for k, v in sorted(self.mmp_w.items())},
            "refusals": dict(self.refusals),
            "warnings": dict(self.warnings),
            # Per ride of `sources`; a ride of its power alone has neither.
            "temperature_c": [*(r.temperature_c for r in self.rides),
                              *(None for _ in self.power_rides)],
            # Smart recording's gaps filled at 1 s, per ride (ride_import.ridden_gaps).
            "filled_s": [*(r.filled_s for r in self.rides), *(0 for _ in self.power_rides)],
            "power_only": {r.source: r.why for r in self.power_rides},
            "drivetrain_efficiency": self.options.drivetrain_efficiency,
            "setups": self._setups(),
        }

    def _setups(self) -> dict[str, Any]:
        """Per setup: its rides and, when fitted, its CdA with the bootstrap sd."""
        out: dict[str, Any] = {}
        for j, name in enumerate(self.setup_names):
            row: dict[str, Any] = {"rides": [r.source for r, k in zip(
                self.rides, self.setup_of_ride, strict=True) if k == j]}
            if self.aero is not None and self.aero.setup_cda_m2:
                row.update(cda_m2=round(self.aero.setup_cda_m2[j], 4),
                           cda_std_m2=round(self.aero.setup_cda_std_m2[j], 4))
            out[name] = row
        return out


def rider_fields() -> set[str]:
    """Field names of `Rider` (the optional ones are written only if the class has them)."""
    return {f.name for f in dataclasses.fields(Rider)}


def load_rides(paths: Sequence[str | Path | Recording], temperature_c: float | None
               ) -> list[RideSeries]:
    """Read and prepare each ride (refusals name the file).

    Raises:
        CalibrationError: a ride cannot be read or prepared.
    """
    return [prepare_ride(_recording(item), temperature_c=temperature_c) for item in paths]


def read_rides(paths: Sequence[str | Path | Recording], temperature_c: float | None
               ) -> list[RideSeries | PowerSeries]:
    """Each ride prepared (`load_rides`); a ride with power but without altitude or speed
    (an indoor trainer's) as its power alone.

    Raises:
        CalibrationError: a ride cannot be read, has no stamps or power, or is too short.
    """
    out: list[RideSeries | PowerSeries] = []
    for item in paths:
        rec = _recording(item)
        try:
            out.append(prepare_ride(rec, temperature_c=temperature_c))
        except MissingChannelError as err:
            out.append(prepare_power(rec, str(err).removeprefix(f"{rec.path}: ")))
    return out


def _recording(item: str | Path | Recording) -> Recording:
    """The ride file read (a `CalibrationError` naming it when it cannot be)."""
    try:
        return item if isinstance(item, Recording) else read_recording(item)
    except CourseError as err:
        raise CalibrationError(str(err)) from None


def ride_courses(rides: list[RideSeries], course: str | None) -> list[Course]:
    """The course of each ride: the given one, or the ride's own track fitted."""
    from itt_planner.course.loader import load_course  # noqa: PLC0415  (SciPy fit, lazy)

    if course is not None:
        return [load_course(course)] * len(rides)
    return [load_course(r.source) for r in rides]


def calibrate(rides: Sequence[str | Path | Recording],
              options: CalibrationOptions = CalibrationOptions(),
              courses: list[Course] | None = None) -> CalibrationResult:
    """Fit one rider to the rides (see the module docstring).

    Raises:
        CalibrationError: a ride is unusable (no power or stamps, another sport, too
            short; one without altitude or speed gives its power alone), or every
            estimator refused (the message lists each reason).
    """
    prepared = read_rides(list(rides), options.temperature_c)
    if options.setups and len(options.setups) != len(prepared):
        raise CalibrationError(f"{len(options.setups)} setups given for {len(prepared)} rides: "
                               "give one --setup per ride, in the rides' order")
    series = [r for r in prepared if isinstance(r, RideSeries)]
    power_rides = [r for r in prepared if isinstance(r, PowerSeries)]
    result = CalibrationResult(sources=[*(r.source for r in series),
                                        *(r.source for r in power_rides)],
                               rider=PRESETS[options.preset], rides=series,
                               power_rides=power_rides, options=options)
    given = tuple(label for label, r in zip(options.setups, prepared, strict=False)
                  if isinstance(r, RideSeries))
    result.setup_names, result.setup_of_ride = _setups(series, given)
    settings = AeroSettings(mass_kg=options.mass_kg,
                            drivetrain_efficiency=options.drivetrain_efficiency,
                            crr_prior=options.crr_prior, allow_simulated=options.allow_virtual,
                            setup_of_ride=tuple(result.setup_of_ride)
                            if len(result.setup_names) > 1 else ())
    try:
        if not series:
            raise CalibrationError("no ride with altitude and speed: " + "; ".join(
                f"{r.source}: {r.why}" for r in power_rides))
        for ride in series:
            check_ride_altitude(ride)
        result.aero = fit_aero(series, settings)
    except CalibrationError as err:
        result.refusals["aero"] = str(err)
    result.mmp_w = mmp_curve([*series, *power_rides])
    for model in ("2p", "3p"):
        try:
            setattr(result, f"cp_{model}", fit_cp(result.mmp_w, model))
        except CalibrationError as err:
            result.refusals[f"cp_{model}"] = str(err)
    if result.cp_2p is not None and (why := submaximal_warning(result.cp_2p, result.mmp_w)):
        result.warnings["cp_2p"] = why
    try:
        if not series:
            raise CalibrationError("no ride with GPS positions and speed")
        result.cornering = fit_cornering(series, courses or ride_courses(series, options.course))
    except (CalibrationError, CourseError) as err:
        result.refusals["cornering"] = str(err)
    if result.aero is None and result.cp_2p is None and result.cornering is None:
        reasons = "; ".join(f"{k}: {v}" for k, v in result.refusals.items())
        raise CalibrationError(f"nothing could be calibrated: {reasons}")
    result.rider = _rider(result, options)
    return result


def _setups(rides: list[RideSeries], given: tuple[str, ...]) -> tuple[list[str], list[int]]:
    """Setup names (first-seen order) and each ride's index among them (`given`: one label
    per ride, or none)."""
    labels = list(given) or [record_setup(Path(r.source)) or "default" for r in rides]
    names = list(dict.fromkeys(labels))
    return names, [names.index(label) for label in labels]


def _rider(result: CalibrationResult, options: CalibrationOptions) -> Rider:
    """The preset with every fitted value put in (the optional fields only if `Rider` has
    them)."""
    values: dict[str, Any] = {"name": options.name}
    known = rider_fields()
    if options.mass_kg is not None:
        values["mass_kg"] = options.mass_kg
    if result.aero is not None:
        values.update(mass_kg=result.aero.mass_kg, drag_area_m2=result.aero.cda_m2,
                      crr=result.aero.crr)
    if result.cp_2p is not None:
        values.update(critical_power_w=result.cp_2p.cp_w, w_prime_j=result.cp_2p.w_prime_j)
        base_max = PRESETS[options.preset].max_power_w
        if result.cp_2p.cp_w >= base_max:
            values["max_power_w"] = max(result.mmp_w.values())
    if "drivetrain_efficiency" in known:
        values["drivetrain_efficiency"] = options.drivetrain_efficiency
    if result.cornering is not None and "max_lateral_accel_mps2" in known:
        values["max_lateral_accel_mps2"] = result.cornering.max_lateral_accel_mps2
    return dataclasses.replace(PRESETS[options.preset], **values)


def rider_yaml(result: CalibrationResult) -> str:
    """The rider as a YAML file for `--rider`, each fitted value's uncertainty beside it."""
    r, opts = result.rider, result.options
    notes: dict[str, str] = {}
    if result.aero is not None:
        a = result.aero
        notes["mass_kg"] = (f"estimated +- {a.mass_std_kg:.1f} kg from the climbs"
                            if a.mass_estimated else "given")
        notes["drag_area_m2"] = (f"+- {a.cda_std_m2:.4f} (bootstrap, {a.n_stretches} stretches, "
                                 f"rho {a.air_density_kgpm3:.3f} kg/m^3)")
        if len(result.setup_names) > 1:
            notes["drag_area_m2"] += f", setup {result.setup_names[result.setup_of_ride[0]]}"
        notes["crr"] = "fixed: " + a.crr_note if a.crr_fixed else f"+- {a.crr_std:.5f}"
    if result.cp_2p is not None:
        c = result.cp_2p
        notes["critical_power_w"] = (f"+- {c.cp_std_w:.1f} W, 2-parameter model on "
                                     f"{c.durations_s[0]}-{c.durations_s[-1]} s, R2 {c.r2:.3f}")
        notes["w_prime_j"] = f"+- {c.w_prime_std_j:.0f} J"
    if result.cornering is not None:
        notes["max_lateral_accel_mps2"] = (
            f"+- {result.cornering.std_mps2:.2f}, lean {result.cornering.max_lean_deg:.1f} deg, "
            f"{len(result.cornering.corners)} corners")
    notes["drivetrain_efficiency"] = "given: wheel power / measured power"
    fitted = ["name", "mass_kg", "drag_area_m2", "crr", "critical_power_w", "w_prime_j",
              "max_power_w", "drivetrain_efficiency", "max_lateral_accel_mps2"]
    base = PRESETS[opts.preset]
    day_winds = [] if result.aero is None else cast(list[dict[str, float]],
                                                    result.aero.as_dict()["wind"])
    winds = [f"# wind of the day fitted on {src}: {w['speed_kmh']} +- {w['std_kmh']} km/h from "
             f"{w['from_deg']:.0f} deg (a condition, not a rider field)"
             for src, w in zip(result.sources, day_winds, strict=False)]
    setups = [f"# CdA of setup {name}: {r.drag_area_m2:.4f} m^2 (--setup)"
              for name, r in result.setup_riders().items()]
    lines = [f"{YAML_HEADER}{', '.join(result.sources)}", *winds, *setups,
             *(f"# refused {k}: {v}" for k, v in result.refusals.items()),
             *(f"# warning {k}: {v}" for k, v in result.warnings.items()),
             *(f"# power only {r.source}: {r.why} (its power is in CP and W')"
               for r in result.power_rides),
             f"preset: {opts.preset}"]
    for name in fitted:
        if name not in rider_fields():
            continue
        value = getattr(r, name)
        if name != "name" and value == getattr(base, name) and name not in notes:
            continue
        if isinstance(value, float):
            text = f"{value:.6g}" if math.isfinite(value) else ".nan"
        else:
            text = str(value) if value is not None else "null"
        lines.append(f"{name}: {text}" + (f"  # {notes[name]}" if name in notes else ""))
    return "\n".join(lines) + "\n"


def write_rider(result: CalibrationResult, path: str | Path) -> Path:
    """Write `rider_yaml(result)` to `path`.

    Raises:
        CalibrationError: the file cannot be written.
    """
    path = Path(path)
    try:
        path.write_text(rider_yaml(result), encoding="utf-8")
    except OSError as err:
        raise CalibrationError(f"{path}: cannot write the rider ({err})") from None
    return path


def write_setup_riders(result: CalibrationResult, path: str | Path) -> list[Path]:
    """With several setups, one rider file per setup beside `path` (`me.yaml` ->
    `me.<setup>.yaml`): the same rider with that setup's CdA.

    Raises:
        CalibrationError: a file cannot be written.
    """
    path = Path(path)
    out = []
    for j, (name, rider) in enumerate(result.setup_riders().items()):
        assert result.aero is not None  # setup_riders() is empty without it
        aero = dataclasses.replace(result.aero, cda_m2=result.aero.setup_cda_m2[j],
                                   cda_std_m2=result.aero.setup_cda_std_m2[j])
        one = dataclasses.replace(result, rider=rider, aero=aero, setup_names=[name],
                                  setup_of_ride=[0] * len(result.sources))
        safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in name)
        out.append(write_rider(one, path.with_name(f"{path.stem}.{safe}{path.suffix}")))
    return out
