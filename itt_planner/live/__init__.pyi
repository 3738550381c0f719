"""Type stub of `itt_planner.live`: its public names, loaded lazily by `__init__.py`."""

from .advice import Advice, Cue, Diagnostic, Level
from .engine import EngineSettings, PacingEngine
from .estimate import StateEstimator
from .estimator_settings import EstimatorSettings
from .samples import GpsFix, PowerReading, Sample, WheelSpeed
from .wprime_balance import WPrimeBalance

__all__ = ["Advice", "Cue", "Diagnostic", "EngineSettings", "EstimatorSettings", "GpsFix",
           "Level", "PacingEngine", "PowerReading", "Sample", "StateEstimator", "WPrimeBalance",
           "WheelSpeed"]
