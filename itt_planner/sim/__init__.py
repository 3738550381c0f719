"""Stage 8, the virtual rider: a closed-loop simulation of a rider following (or not) the
engine's advice on the 3D model, and the demo ride logs made from it.

    hairpin     the short technical test course of the closed-loop tests
    sensors     simulated GPS, wheel-speed and power sensors; smart recording's thinning
    scenarios   how the truth differs from the belief, and the rider's policy
    behaviour   the rider's lag, noise and controller gains; the grip the planner assumes
    step        one time step of the 3D model under the rider's controller (CasADi)
    reference   the profile and line the rider follows (plan or advice)
    loop        `simulate_ride`: sensors -> engine -> rider -> model, step by step
    compare     the three policies on one truth (`itt-planner simulate`)
    demo_bags   a simulated ride written as an MCAP ride log
"""

from itt_planner.sim.behaviour import RiderBehaviour, planning_conditions
from itt_planner.sim.compare import compare_policies
from itt_planner.sim.demo_bags import record_simulated_ride
from itt_planner.sim.hairpin import HAIRPIN_COURSE, hairpin_course
from itt_planner.sim.loop import SimResult, simulate_ride
from itt_planner.sim.scenarios import Policy, Scenario, ScenarioSettings
from itt_planner.sim.sensors import Sensors, SensorSettings, sensor_samples, smart_recording

__all__ = ["HAIRPIN_COURSE", "Policy", "RiderBehaviour", "Scenario", "ScenarioSettings",
           "SensorSettings", "Sensors", "SimResult", "compare_policies", "hairpin_course",
           "planning_conditions", "record_simulated_ride", "sensor_samples", "simulate_ride",
           "smart_recording"]
