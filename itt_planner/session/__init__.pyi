"""Type stub of `itt_planner.session`: its public names, loaded lazily by `__init__.py`."""

from .config import SessionConfig, build_engine
from .replay import ReplayResult, ReplaySettings, replay_ride
from .ride_session import RideSession

__all__ = ["ReplayResult", "ReplaySettings", "RideSession", "SessionConfig", "build_engine",
           "replay_ride"]
