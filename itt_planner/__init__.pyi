"""Type stub of `itt_planner`: its public names, loaded lazily by `__init__.py`."""

from .course.geometry import Corner, Course, GeoOrigin
from .errors import CourseError, IttError, RideLogError, RiderError, SolveError
from .live.advice import Advice, Cue, Diagnostic, Level
from .live.samples import GpsFix, PowerReading, WheelSpeed
from .model.conditions import Conditions
from .model.rider import PRESETS, Rider, load_rider
from .model.state import RiderState
from .ocp.plan import Plan

__all__ = [
    "PRESETS",
    "Advice",
    "Conditions",
    "Corner",
    "Course",
    "CourseError",
    "Cue",
    "Diagnostic",
    "GeoOrigin",
    "GpsFix",
    "IttError",
    "Level",
    "Plan",
    "PowerReading",
    "RideLogError",
    "Rider",
    "RiderError",
    "RiderState",
    "SolveError",
    "WheelSpeed",
    "load_rider",
]
