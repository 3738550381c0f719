"""Type stub of `itt_planner.logs`: its public names, loaded lazily by `__init__.py`."""

from .ride_import import ImportSummary, import_ride
from .ridelog import RideLogReader, read_ride_log
from .ridelog_writer import RideLogWriter, RideMetadata

__all__ = ["ImportSummary", "RideLogReader", "RideLogWriter", "RideMetadata", "import_ride",
           "read_ride_log"]
