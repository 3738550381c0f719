"""Type stub of `itt_planner.sim`: its public names, loaded lazily by `__init__.py`."""

from .behaviour import RiderBehaviour, planning_conditions
from .compare import compare_policies
from .demo_bags import record_simulated_ride
from .hairpin import HAIRPIN_COURSE, hairpin_course
from .loop import SimResult, simulate_ride
from .scenarios import Policy, Scenario, ScenarioSettings
from .sensors import Sensors, SensorSettings, sensor_samples, smart_recording

__all__ = ["HAIRPIN_COURSE", "Policy", "RiderBehaviour", "Scenario", "ScenarioSettings",
           "SensorSettings", "Sensors", "SimResult", "compare_policies", "hairpin_course",
           "planning_conditions", "record_simulated_ride", "sensor_samples", "simulate_ride",
           "smart_recording"]
