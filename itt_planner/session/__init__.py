"""One ride session for both edges (the ROS node and the embedded replay): course, rider,
plan and engine built from a `SessionConfig`, samples in, advice out to sinks (MCAP log,
Rerun, a publish callback) (`ride_session`); `replay` reads and paces a ride log into it."""

from itt_planner.session.replay import ReplayResult, ReplaySettings, replay_ride
from itt_planner.session.ride_session import RideSession, SessionConfig, build_engine

__all__ = ["ReplayResult", "ReplaySettings", "RideSession", "SessionConfig", "build_engine",
           "replay_ride"]
