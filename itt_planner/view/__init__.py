"""Stage 6, what people look at: Rerun logging of a ride (`rerun_log`, laid out by
`rerun_blueprint`, sent by `rerun_sink`) and the static HTML/PNG report (`report`, reading a
replayed ride with `ride_report`)."""

from itt_planner.view.report import ReportSettings, write_report
from itt_planner.view.rerun_blueprint import default_blueprint
from itt_planner.view.rerun_log import RideRecorder
from itt_planner.view.rerun_sink import RerunSink, open_recording

__all__ = ["RerunSink", "ReportSettings", "RideRecorder", "default_blueprint",
           "open_recording", "write_report"]
