"""The virtual rider: a closed-loop simulation of a rider following (or not) the engine's
advice on the 3D model, with simulated sensors and scenarios (`simulate`), and the demo
ride logs made from it (`demo_bags`)."""

from itt_planner.sim.demo_bags import record_simulated_ride
from itt_planner.sim.simulate import Scenario, SimResult, compare_policies, simulate_ride

__all__ = ["Scenario", "SimResult", "compare_policies", "record_simulated_ride",
           "simulate_ride"]
