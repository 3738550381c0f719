"""Stage 2, rider and physics: the rider's parameters (`rider`), the weather and grip
(`conditions`), the W' balance model (`wprime`), the rider's state (`state`) and the
CasADi spatial dynamics of model.md E1-E9 (`dynamics`, 3D and 1D)."""

from itt_planner.model.conditions import Conditions
from itt_planner.model.dynamics import SpatialModel, build_model, steady_speed_mps
from itt_planner.model.rider import PRESETS, Rider, load_rider
from itt_planner.model.state import RiderState
from itt_planner.model.wprime import WPrimeModel

__all__ = ["PRESETS", "Conditions", "Rider", "RiderState", "SpatialModel", "WPrimeModel",
           "build_model", "load_rider", "steady_speed_mps"]
