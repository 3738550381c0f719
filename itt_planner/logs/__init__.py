"""Stage 5, ride logs: MCAP ride logs in the ROS 2 profile (`ridelog`: the format and
reading, `ridelog_writer`: writing) and the import of ride files (FIT/GPX/TCX/CSV) into
them (`ride_import`)."""

from itt_planner.logs.ride_import import ImportSummary, import_ride
from itt_planner.logs.ridelog import RideLogReader, read_ride_log
from itt_planner.logs.ridelog_writer import RideLogWriter, RideMetadata

__all__ = ["ImportSummary", "RideLogReader", "RideLogWriter", "RideMetadata", "import_ride",
           "read_ride_log"]
