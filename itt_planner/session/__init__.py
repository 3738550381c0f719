"""One ride session for both edges (the ROS node and the embedded replay): what decides
the advice and the engine built from it (`config`), samples in and advice out on the
stamp clock (`ride_session`) to sinks (`sinks`: MCAP log, Rerun, a publish callback);
`replay` reads and paces a ride log into it."""

from itt_planner.session.config import SessionConfig, build_engine
from itt_planner.session.replay import ReplayResult, ReplaySettings, replay_ride
from itt_planner.session.ride_session import RideSession

__all__ = ["ReplayResult", "ReplaySettings", "RideSession", "SessionConfig", "build_engine",
           "replay_ride"]
