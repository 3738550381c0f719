"""Stage 4, the live loop: input samples (`samples`), state estimation (`estimate`), the
W'/CP belief (`cp_monitor`), the pacing engine (`engine`: samples in, `Advice` out, clocked
by message stamps), re-solves of the rest of the course (`course_replan`), the shaping of
advice a rider can follow (`advice_shaping`) and the engine's health (`health`).

Nothing here imports ride logs, ROS or Rerun."""

from itt_planner.live.advice import Advice, Cue, Diagnostic, Level
from itt_planner.live.engine import EngineSettings, PacingEngine
from itt_planner.live.estimate import EstimatorSettings, StateEstimator
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed

__all__ = ["Advice", "Cue", "Diagnostic", "EngineSettings", "EstimatorSettings", "GpsFix",
           "Level", "PacingEngine", "PowerReading", "StateEstimator", "WheelSpeed"]
