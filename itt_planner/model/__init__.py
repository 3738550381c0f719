"""Stage 2, rider and physics: the rider's parameters (`rider`), the weather and grip
(`conditions`), the W' balance model (`wprime`), the rider's state (`state`), the CasADi
spatial dynamics of model.md E1-E9 (`dynamics`, 3D, 1D and steady-lean 3D), the numeric
parameter vector and road data they take (`params`) and the steady-state speeds of the
power balance (`steady`)."""

from itt_planner.model.conditions import Conditions
from itt_planner.model.dynamics import SpatialModel, build_model
from itt_planner.model.params import ModelParams
from itt_planner.model.rider import PRESETS, Rider, load_rider
from itt_planner.model.state import RiderState
from itt_planner.model.steady import speed_bound_mps, steady_speed_mps
from itt_planner.model.wprime import WPrimeModel

__all__ = ["PRESETS", "Conditions", "ModelParams", "Rider", "RiderState", "SpatialModel",
           "WPrimeModel", "build_model", "load_rider", "speed_bound_mps", "steady_speed_mps"]
