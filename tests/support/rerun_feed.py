"""Feed engine-like events to a `RideRecorder`, as the replay and the node do."""

from __future__ import annotations

from itt_planner.live.advice import Advice
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed
from itt_planner.model.state import RiderState
from itt_planner.view.rerun_log import RideRecorder


def record(recorder: RideRecorder, events: list) -> None:
    """Feed engine-like events to the recorder, as the replay and the node do."""
    for ev in events:
        if isinstance(ev, PowerReading):
            recorder.log_power(ev)
        elif isinstance(ev, WheelSpeed):
            recorder.log_speed(ev)
        elif isinstance(ev, GpsFix):
            recorder.log_gps(ev, None)
        elif isinstance(ev, RiderState):
            recorder.log_state(ev)
        elif isinstance(ev, Advice):
            recorder.log_advice(ev)
        else:
            recorder.log_diagnostics(ev)
