"""itt-planner: race support for cycling individual time trials.

The ROS-free core: course geometry, rider models, the pacing-and-cornering optimal
control problems (CasADi), state estimation, the pacing engine, ride logs, Rerun
logging and the CLI. See docs in README.md and the physics in model.md.
"""

from itt_planner.course.geometry import Corner, Course, GeoOrigin
from itt_planner.errors import CourseError, IttError, RideLogError, RiderError, SolveError
from itt_planner.live.advice import Advice, Cue, Diagnostic, Level
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import PRESETS, Rider, load_rider
from itt_planner.model.state import RiderState
from itt_planner.ocp.plan import Plan

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
