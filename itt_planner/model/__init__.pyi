"""Type stub of `itt_planner.model`: its public names, loaded lazily by `__init__.py`."""

from .conditions import Conditions
from .dynamics import SpatialModel, build_model
from .params import ModelParams
from .rider import PRESETS, Rider, load_rider
from .state import RiderState
from .steady import speed_bound_mps, steady_speed_mps
from .wprime import WPrimeModel

__all__ = ["PRESETS", "Conditions", "ModelParams", "Rider", "RiderState", "SpatialModel",
           "WPrimeModel", "build_model", "load_rider", "speed_bound_mps", "steady_speed_mps"]
