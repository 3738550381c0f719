"""Rider + bicycle parameters (model.md section 7): presets and YAML overrides.

A `Rider` is a frozen, validated record in SI units with the unit in every field name.
It is built once at the edge (CLI, ROS parameters) and passed down; the core never reads
files for it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import yaml

from itt_planner.errors import RiderError

#: Air density of the paper calibration (model.md section 7), kg/m^3.
PAPER_AIR_DENSITY_KGPM3 = 1.23
#: Drag area C_D * A_f implied by the paper's k_v = 0.13 kg/m at A_f = 0.35 m^2.
_PAPER_CD = 0.13 / (0.5 * 0.35 * PAPER_AIR_DENSITY_KGPM3)


@dataclass(frozen=True)
class Rider:
    """Rider and bicycle, model.md section 7. Defaults are the paper calibration."""

    name: str = "paper"
    mass_kg: float = 77.0
    roll_inertia_kgm2: float = 77.0
    com_height_m: float = 1.2
    drag_area_m2: float = _PAPER_CD * 0.35
    crr: float = 0.0035
    wheelbase_m: float = 1.4
    steer_max_rad: float = 0.52
    power_rate_max_wps: float = 50.0
    # Not published (model.md section 7): ~1 rad/s is a brisk but human steering rate.
    steer_rate_max_radps: float = 1.0
    critical_power_w: float = 440.0
    max_power_w: float = 1870.0
    w_prime_j: float = 22000.0
    pedal_lean_max_rad: float = math.radians(20.0)
    #: The rider's own cornering limit (model.md section 7: amateurs corner far below the
    #: grip limit): C16 uses `a_y <= min(mu_y g, max_lateral_accel_mps2)`. None: grip only.
    max_lateral_accel_mps2: float | None = None
    #: Power at the wheel = efficiency x crank power in E3 (chain, bearings); E9 and the
    #: advised power stay crank power. 1.0 keeps the paper's model.
    drivetrain_efficiency: float = 1.0

    def __post_init__(self) -> None:
        positive = (
            "mass_kg", "roll_inertia_kgm2", "com_height_m", "drag_area_m2", "wheelbase_m",
            "steer_max_rad", "power_rate_max_wps", "steer_rate_max_radps", "critical_power_w",
            "max_power_w", "w_prime_j", "pedal_lean_max_rad",
        )
        for field in positive:
            value = getattr(self, field)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                msg = (f"rider {self.name!r}: {field} must be a positive finite number, "
                       f"got {value!r}")
                raise RiderError(msg)
        if not 0 <= self.crr < 0.1:
            msg = f"rider {self.name!r}: crr must be in [0, 0.1), got {self.crr!r}"
            raise RiderError(msg)
        lateral = self.max_lateral_accel_mps2
        if lateral is not None and (not isinstance(lateral, (int, float))
                                    or not math.isfinite(lateral) or lateral <= 0):
            msg = (f"rider {self.name!r}: max_lateral_accel_mps2 must be a positive finite "
                   f"number or null, got {lateral!r}")
            raise RiderError(msg)
        eta = self.drivetrain_efficiency
        if not isinstance(eta, (int, float)) or not 0.5 <= eta <= 1.0:
            msg = f"rider {self.name!r}: drivetrain_efficiency must be in [0.5, 1], got {eta!r}"
            raise RiderError(msg)
        if self.critical_power_w >= self.max_power_w:
            msg = (f"rider {self.name!r}: critical_power_w ({self.critical_power_w}) must be below "
                   f"max_power_w ({self.max_power_w})")
            raise RiderError(msg)
        if self.steer_max_rad >= math.pi / 2:
            msg = f"rider {self.name!r}: steer_max_rad must be below pi/2, got {self.steer_max_rad}"
            raise RiderError(msg)


PRESETS: dict[str, Rider] = {
    "paper": Rider(),
    # The three virtual riders of model.md section 7; k_v scales with frontal area.
    "typical": Rider(name="typical", mass_kg=77.0, drag_area_m2=_PAPER_CD * 0.35,
                     critical_power_w=386.0, w_prime_j=22000.0),
    "specialist": Rider(name="specialist", mass_kg=88.0, drag_area_m2=_PAPER_CD * 0.35,
                        critical_power_w=478.0, w_prime_j=22000.0),
    "climber": Rider(name="climber", mass_kg=61.0, drag_area_m2=_PAPER_CD * 0.28,
                     critical_power_w=275.0, w_prime_j=22000.0),
}


def load_rider(spec: str | Path) -> Rider:
    """Return a preset by name, or a rider read from a YAML file.

    The YAML file may name a `preset` to start from (default `paper`) and override any
    field of `Rider`.

    Raises:
        RiderError: unknown preset, unreadable file, unknown field or invalid value.
    """
    text = str(spec)
    if text in PRESETS:
        return PRESETS[text]
    path = Path(text)
    if not path.is_file():
        msg = f"unknown rider {text!r}: not a preset ({', '.join(PRESETS)}) nor a file"
        raise RiderError(msg)
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except (OSError, yaml.YAMLError) as err:
        msg = f"could not read rider file {path}: {err}"
        raise RiderError(msg) from None
    if not isinstance(data, dict):
        msg = f"rider file {path}: expected a mapping of fields, got {type(data).__name__}"
        raise RiderError(msg)
    base = PRESETS.get(str(data.pop("preset", "paper")))
    if base is None:
        msg = f"rider file {path}: unknown preset; choose one of {', '.join(PRESETS)}"
        raise RiderError(msg)
    known = {f.name for f in dataclasses.fields(Rider)}
    unknown = sorted(set(data) - known)
    if unknown:
        msg = f"rider file {path}: unknown field(s) {', '.join(unknown)}"
        raise RiderError(msg)
    data.setdefault("name", path.stem)
    try:
        return dataclasses.replace(base, **data)
    except RiderError as err:
        raise RiderError(f"rider file {path}: {err}") from None
    except TypeError as err:
        raise RiderError(f"rider file {path}: {err}") from None
