"""Type stub of `itt_planner.view`: its public names, loaded lazily by `__init__.py`."""

from .report import ReportSettings, write_report
from .rerun_blueprint import default_blueprint
from .rerun_log import RideRecorder
from .rerun_sink import RerunSink, open_recording

__all__ = ["ReportSettings", "RerunSink", "RideRecorder", "default_blueprint",
           "open_recording", "write_report"]
