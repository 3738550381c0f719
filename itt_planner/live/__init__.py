"""Stage 4, the live loop: input samples (`samples`), state estimation (`estimate`, with
map matching in `map_match`), the W' balance and the CP in use (`wprime_balance`), CP
refits (`cp_monitor`), the pacing engine (`engine`: samples in, `Advice` out, clocked by
message stamps) with the plan in force (`plan_in_force`), the horizon's solves
(`horizon_step`) and re-solves of the rest of the course (`course_replan`), the shaping
of advice a rider can follow (`advice_shaping`) and the engine's health (`health`).

Nothing here imports ride logs, ROS or Rerun."""

from itt_planner.live.advice import Advice, Cue, Diagnostic, Level
from itt_planner.live.engine import EngineSettings, PacingEngine
from itt_planner.live.estimate import EstimatorSettings, StateEstimator
from itt_planner.live.samples import GpsFix, PowerReading, Sample, WheelSpeed
from itt_planner.live.wprime_balance import WPrimeBalance

__all__ = ["Advice", "Cue", "Diagnostic", "EngineSettings", "EstimatorSettings", "GpsFix",
           "Level", "PacingEngine", "PowerReading", "Sample", "StateEstimator", "WPrimeBalance",
           "WheelSpeed"]
